"""The MuJoCo, PyBullet and SAPIEN snippets of docs/convert.md, run as written, pose parts as rsart does."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

DOC = Path(__file__).resolve().parents[2] / "docs" / "convert.md"


def _snippet(engine: str) -> str:
    """The python block of docs/convert.md that imports ``engine``."""
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S)
    [code] = [b for b in blocks if re.search(rf"^import {engine}$", b, re.M)]
    return code


@pytest.fixture(scope="module")
def pm_object(tmp_path_factory, partnet_root):
    """45213 (one hinge, two slides) converted by `rsart convert` at a small resolution."""
    from rsart.cli import main

    out = tmp_path_factory.mktemp("phys") / "pm-45213"
    assert main(["convert", "partnet-mobility", str(partnet_root / "45213"), "--out", str(out),
                 "--resolution", "48", "-q"]) == 0
    return out


def _run(engine, obj_dir, state):
    code = _snippet(engine).replace('"objects/pm-45213"', repr(str(obj_dir))).replace('"m3"', repr(state))
    ns: dict = {}
    exec(compile(code, f"docs/convert.md ({engine})", "exec"), ns)
    return ns


def _expected_part_frames(obj, state):
    """(R, t) of every movable part in ``state``: rsart's rest -> posed rigid motion of that part."""
    out = {}
    rest = obj.twin.posed_meshes({j.name: 0.0 for j in obj.joints})
    posed = obj.twin.posed_meshes(obj.states[state].values)
    for j in obj.joints:
        a, b = rest[j.child].vertices, posed[j.child].vertices
        ca, cb = a.mean(0), b.mean(0)
        u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
        R = (u @ vt).T
        if np.linalg.det(R) < 0:
            u[:, -1] *= -1
            R = (u @ vt).T
        out[j.name] = (R, cb - R @ ca)
    return out


def _check(frames_rest, frames_state, expected):
    for name, (R_exp, t_exp) in expected.items():
        (R0, p0), (R1, p1) = frames_rest[name], frames_state[name]
        R = R1 @ R0.T  # engine's motion of the link frame from rest to the state
        t = p1 - R @ p0
        np.testing.assert_allclose(R, R_exp, atol=1e-6, err_msg=name)
        np.testing.assert_allclose(t, t_exp, atol=1e-6, err_msg=name)


def test_mujoco_snippet(pm_object):
    import rsart
    from scipy.spatial.transform import Rotation

    obj = rsart.load(pm_object)
    frames = {}
    for state in ("m0", "m3"):
        ns = _run("mujoco", pm_object, state)
        m, d = ns["model"], ns["data"]
        frames[state] = {j.name: (Rotation.from_quat(d.xquat[m.body(obj.parts[j.child].name).id], scalar_first=True)
                                  .as_matrix(), d.xpos[m.body(obj.parts[j.child].name).id].copy()) for j in obj.joints}
    assert obj.states["m0"].values != obj.states["m3"].values
    _check(frames["m0"], frames["m3"], _expected_part_frames(obj, "m3"))


def test_pybullet_snippet(pm_object):
    pybullet = pytest.importorskip("pybullet", reason="pybullet is not installed (pip install pybullet==3.2.7)")
    import rsart
    from scipy.spatial.transform import Rotation

    obj = rsart.load(pm_object)
    frames = {}
    for state in ("m0", "m3"):
        ns = _run("pybullet", pm_object, state)
        body, client, idx = ns["body"], ns["client"], ns["joint_index"]
        fr = {}
        for j in obj.joints:
            pos, orn = pybullet.getLinkState(body, idx[j.name], physicsClientId=client)[4:6]
            fr[j.name] = (Rotation.from_quat(orn).as_matrix(), np.array(pos))
        frames[state] = fr
        pybullet.disconnect(client)
    _check(frames["m0"], frames["m3"], _expected_part_frames(obj, "m3"))


def test_sapien_snippet(pm_object):
    pytest.importorskip("sapien", reason="sapien is not installed (pip install sapien==3.0.3)")
    import rsart
    from scipy.spatial.transform import Rotation

    obj = rsart.load(pm_object)
    frames = {}
    for state in ("m0", "m3"):
        ns = _run("sapien", pm_object, state)
        poses = {link.name: link.entity_pose for link in ns["art"].get_links()}
        frames[state] = {j.name: (Rotation.from_quat(poses[obj.parts[j.child].name].q, scalar_first=True).as_matrix(),
                                  np.array(poses[obj.parts[j.child].name].p, dtype=float)) for j in obj.joints}
    _check(frames["m0"], frames["m3"], _expected_part_frames(obj, "m3"))
