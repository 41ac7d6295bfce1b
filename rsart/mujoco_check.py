"""Check that a twin's URDF loads in MuJoCo and that MuJoCo's kinematics agree with rsart's.

MuJoCo reads URDF directly (``mujoco.MjModel.from_xml_path``); rsart's URDF carries a
``<mujoco><compiler .../></mujoco>`` block so visual meshes are kept and static bodies are not fused.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .errors import RsartError
from .extras import imported
from .kinematics import Twin


def load_mujoco(urdf_path: str | os.PathLike):
    """Load a URDF into a ``mujoco.MjModel``; raise RsartError naming the file on failure."""
    mujoco = imported("mujoco", what="MuJoCo checks")

    try:
        return mujoco.MjModel.from_xml_path(str(urdf_path))
    except Exception as e:
        raise RsartError(f"{urdf_path}: MuJoCo cannot load it: {e}") from None


def mujoco_pose_error(twin: Twin, urdf_path: str | os.PathLike, values: dict[str, float]) -> float:
    """Max distance (m) between rsart's and MuJoCo's part positions of each part's mesh bounding-box corners at ``values``."""
    mujoco = imported("mujoco", what="MuJoCo checks")

    model = load_mujoco(urdf_path)
    data = mujoco.MjData(model)
    for name, v in values.items():
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            raise RsartError(f"{urdf_path}: MuJoCo model has no joint {name!r}")
        data.qpos[model.jnt_qposadr[jid]] = v
    mujoco.mj_kinematics(model, data)
    T = twin.pose(values)
    frame = {0: np.zeros(3)}
    for j in twin.joints:
        frame[j.child] = np.asarray(j.origin, dtype=float)
    err = 0.0
    for p in twin.parts:
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, p.name)
        if bid < 0:
            raise RsartError(f"{urdf_path}: MuJoCo model has no body {p.name!r}")
        if not len(p.mesh.vertices):
            continue
        corners = np.array(np.meshgrid(*p.mesh.bounds.T)).reshape(3, -1).T
        ours = corners @ T[p.index][:3, :3].T + T[p.index][:3, 3]
        R = data.xmat[bid].reshape(3, 3)
        theirs = (corners - frame[p.index]) @ R.T + data.xpos[bid]
        err = max(err, float(np.abs(ours - theirs).max()))
    return err
