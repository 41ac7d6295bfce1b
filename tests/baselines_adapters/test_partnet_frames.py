"""On real PartNet-Mobility objects (RSART_PARTNET_ROOT): the GT joints an export writes in the ``y-up``
frame are mobility_v2.json's own axes, and in the ``paris`` frame they are those turned by PARIS's
R_coord — i.e. the frames are the peers' frames, not just self-consistent."""
from __future__ import annotations

import json

import numpy as np
import pytest

from baselines_adapters.geometry import Z_UP_FROM_Y_UP, MethodFrame
from baselines_adapters.gt_files import write_gt
from rsart.states import protocol_states


def _line_distance(o1, d1, o2, d2) -> float:
    n = np.cross(d1, d2)
    if np.linalg.norm(n) < 1e-9:
        return float(np.linalg.norm(np.cross(o2 - o1, d1)))
    return float(abs(np.dot(n / np.linalg.norm(n), o2 - o1)))


@pytest.mark.parametrize("pid", ["45213", "148", "8867"])
def test_exported_gt_axes_are_partnet_axes(partnet_root, pid, tmp_path):
    from rsart.sources.partnet import read_mobility_v2, read_partnet

    twin, info, _, _ = read_partnet(partnet_root / pid)
    mob = read_mobility_v2(partnet_root / pid / "mobility_v2.json")
    states, ev = protocol_states(twin.joints)
    start = next(s for s in states if s.id == ev["start"])
    end = next(s for s in states if s.id == ev["end"])
    joints = sorted(twin.joints, key=lambda j: j.child)
    checked = 0
    for frame, R in (("y-up", np.eye(3)), ("paris", Z_UP_FROM_Y_UP)):
        gt = tmp_path / frame
        write_gt(gt, twin, joints, start.values, end.values, MethodFrame.named(frame))
        ti = json.loads((gt / "trans.json").read_text())["trans_info"]
        ti = ti if isinstance(ti, list) else [ti]
        for j, e in zip(joints, ti):
            rec = j.extra.get("mobility_v2")
            if not rec or not rec.get("agrees") or j.parent != 0:
                continue
            same = [m for m in mob.values() if (m.get("jointData") or {}).get("axis", {}).get("direction") == rec["direction"]]
            raw = same[0]
            d_raw = R @ np.asarray(raw["jointData"]["axis"]["direction"], float)
            d_raw /= np.linalg.norm(d_raw)
            o_raw = R @ np.asarray(raw["jointData"]["axis"]["origin"], float)
            d = np.asarray(e["axis"]["d"])
            assert abs(abs(np.dot(d, d_raw)) - 1) < 1e-6, (pid, j.name, frame, d, d_raw)
            if j.type == "revolute" and len(same) == 1:  # the entry is identified: its pivot line must match
                assert _line_distance(np.asarray(e["axis"]["o"]), d, o_raw, d_raw) < 1e-5, (pid, j.name, frame)
            checked += 1
    assert checked > 0
