"""Discovery on a real PartNet-Mobility object (45213: a cabinet with a door and two drawers) with a 'perfect'
field: real part shapes, no training. Needs RSART_PARTNET_ROOT (skips otherwise)."""
import os
from pathlib import Path

import numpy as np
import pytest

import rsart
from fixture_object import perfect_field, render_views, ring_cameras
from pd2gs.discovery import DiscoveryConfig
from pd2gs.discovery.pipeline import discover, method_block
from pd2gs.discovery.submission import write_submission
from rsart.evaluation import load_ground_truth, read_submission, score_submission

ROOT = os.environ.get("RSART_PARTNET_ROOT")
pytestmark = pytest.mark.skipif(not ROOT, reason="RSART_PARTNET_ROOT is not set (PartNet-Mobility sample objects)")


def test_storage_furniture_45213(tmp_path):
    from rsart.sources.partnet import read_partnet
    from rsart.twin_io import write_object
    src = Path(ROOT) / "45213"
    if not src.is_dir():
        pytest.skip(f"{src} missing")
    obj_dir = tmp_path / "pm-45213"
    twin = read_partnet(src)[0]       # the full importer's watertight copies take ~50 s; not needed here
    write_object(twin, obj_dir, object_id="pm-45213", category="storage", units="scene",
                 source={"kind": "partnet-mobility", "id": "45213"}, write_usd=False)
    obj = rsart.load(obj_dir)
    states = [s.id for s in obj.meta.states if s.kind == "multi"]
    render_views(obj_dir, obj.twin, obj.meta, states, ring_cameras(obj.twin, 12))
    obj = rsart.load(obj_dir)
    lo, hi = obj.twin.bounds(obj.twin.zero_config())
    fld, _ = perfect_field(obj.twin, obj.meta, states, n=3000, jitter=0.001 * float(np.linalg.norm(hi - lo)))
    # centre-based joints: the exact field's flat part colours do not reproduce the views (no photometric fit)
    cfg = DiscoveryConfig(joint_rule="bic", split_disconnected=True, refine=False, mesh_views=8, mode="paper")
    res = discover(fld, obj, cfg)
    # two drawers with equal limits share one motion; the spatial split separates them
    assert res.diagnostics["count"]["n"] == 2 and res.diagnostics["count"]["after_spatial_split"] == 3
    sub = write_submission({obj.id: res}, tmp_path / "sub", method_block(cfg, 4), {})
    gt = load_ground_truth(obj_dir)
    parsed, problems = read_submission(sub, gt)
    assert problems == []
    m = score_submission(parsed, gt)[0][obj.id]["metrics"]
    assert m["count_acc"] == 1.0 and m["type_acc"] == 1.0
    assert m["axis_ang"] < 1.0 and m["axis_pos"] < 0.1
    assert m["part_motion_rev"] < 1.0 and m["part_motion_pri"] < 0.01
