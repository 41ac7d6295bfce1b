"""Small rendered objects (cabinet: revolute lid + prismatic drawer; lamp: chained revolute joints),
rendered by rsart.render with the two-state and single-joint protocols (few tiny views: fast), and
helpers to score a submission with rsart.evaluation."""
from __future__ import annotations

from pathlib import Path

import pytest

from rsart.camera import Intrinsics
from rsart.twin_io import write_object

from tests.baselines_adapters.ba_helpers import score
from tests.conftest import make_cabinet, make_lamp

SIZE = (64, 48)


def _render(obj_dir: Path, protocol: str) -> Path:
    from rsart.render.frame import RenderOptions
    from rsart.render.runner import RenderJob, render_object_dir

    job = RenderJob(protocol=protocol, views=3, test_views=1,
                    options=RenderOptions(intrinsics=Intrinsics.from_fov(SIZE[0], SIZE[1], 50.0), rgb_backend="raycast"))
    render_object_dir(obj_dir, job, workers=1, progress=False)
    return obj_dir


def _object(root: Path, twin, oid: str, protocol: str) -> Path:
    out = root / protocol / oid
    write_object(twin, out, object_id=oid, category="test", source={"kind": "procedural", "id": "test"})
    return _render(out, protocol)


@pytest.fixture(scope="session")
def objects(tmp_path_factory) -> dict[str, Path]:
    """{"cabinet/two-state", "cabinet/single-joint", "lamp/single-joint", "lamp/two-state"} -> object folders."""
    root = tmp_path_factory.mktemp("objects")
    out = {}
    for name, make in (("cabinet", make_cabinet), ("lamp", make_lamp)):
        for protocol in ("two-state", "single-joint"):
            out[f"{name}/{protocol}"] = _object(root, make(), f"{name}-0000", protocol)
    return out


@pytest.fixture(scope="session")
def gt_scores(tmp_path_factory, objects) -> dict[str, dict]:
    """The ground-truth reference submission's scores per object folder key (the Chamfer sampling floor)."""
    from rsart.evaluation import load_ground_truth, make_gt_submission

    out = {}
    root = tmp_path_factory.mktemp("gt-subs")
    for key, d in objects.items():
        p = make_gt_submission(load_ground_truth(d), root / key.replace("/", "_"))
        out[key] = score(p, d)
    return out
