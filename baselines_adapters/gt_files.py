"""The peers' ground-truth folder (PARIS ``preprocess.py`` layout, read by PARIS, DTArt and ArtGS):

    <gt>/trans.json
    <gt>/{start,end}/{state}_rotate.ply            whole object
    <gt>/{start,end}/{state}_static_rotate.ply     parts that do not move in this run
    <gt>/{start,end}/{state}_dynamic[_i]_rotate.ply  moving part i (suffix only with >= 2 joints)

``trans.json``: ``{"input": {...}, "trans_info": {"axis": {"o", "d"}, "type": "rotate"|"translate",
"rotate"|"translate": {"l": start, "r": end}}}`` — ``trans_info`` is a list with one entry per moving
joint when there are several. Values ``l``/``r`` are **degrees** for ``rotate`` and scene units for
``translate``; ``o``/``d`` are in the method frame (geometry.MethodFrame) at the start state.
Every number is written as a float (DTArt's ``list_to_array`` returns None for JSON integers). The
suffix ``_rotate`` means "rotated to z-up", not a revolute joint.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import trimesh

from rsart.format import Joint
from rsart.io import atomic_write_bytes, write_json
from rsart.kinematics import Twin

from .geometry import MethodFrame


def floats(x) -> list | float:
    """Nested lists of Python floats (never ints) from numbers/arrays."""
    if isinstance(x, (list, tuple, np.ndarray)):
        return [floats(v) for v in x]
    return float(x)


def trans_entry(joint: Joint, origin: np.ndarray, axis: np.ndarray, l: float, r: float) -> dict:
    """One ``trans_info`` entry; ``l``/``r`` in rad (revolute) or units (prismatic), written in deg / units."""
    kind = "rotate" if joint.type == "revolute" else "translate"
    lr = (math.degrees(l), math.degrees(r)) if kind == "rotate" else (l, r)
    return {"axis": {"o": floats(origin), "d": floats(axis)}, "type": kind,
            kind: {"l": float(lr[0]), "r": float(lr[1])}}


def subtree(twin: Twin, part: int) -> list[int]:
    """``part`` and every part below it in the kinematic tree."""
    out = [part]
    for j in twin.joints:
        if j.parent == part:
            out += subtree(twin, j.child)
    return out


def _ply(mesh: trimesh.Trimesh) -> bytes:
    return trimesh.exchange.ply.export_ply(trimesh.Trimesh(mesh.vertices, mesh.faces, process=False), encoding="binary")


def _concat(meshes: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    ms = [trimesh.Trimesh(m.vertices, m.faces, process=False) for m in meshes if len(m.faces)]
    return trimesh.util.concatenate(ms) if ms else trimesh.Trimesh()


def write_gt(gt_dir: Path, twin: Twin, joints: list[Joint], start_values: dict[str, float],
             end_values: dict[str, float], frame: MethodFrame) -> dict:
    """Write the GT folder for a run in which ``joints`` move from ``start_values`` to ``end_values``.

    Moving part i = the child of ``joints[i]`` (two-state: that part alone) — or, for a single moving
    joint, its whole subtree (single-joint runs: children move with their parent). Returns trans.json's dict.
    """
    single = len(joints) == 1
    moving: list[list[int]] = []
    for j in joints:
        moving.append(subtree(twin, j.child) if single else [j.child])
    moved = {p for grp in moving for p in grp}
    static = [p.index for p in twin.parts if p.index not in moved]
    axes = twin.posed_axes(start_values)
    entries = []
    for j in joints:
        o, a = axes[j.name]
        entries.append(trans_entry(j, frame.points_to_method(o), frame.dirs_to_method(a),
                                   start_values[j.name], end_values[j.name]))
    trans = {"input": {"joint_ids": [float(j.child) for j in joints], "source": "rsart"},
             "trans_info": entries[0] if single else entries}
    write_json(gt_dir / "trans.json", trans)
    for name, values in (("start", start_values), ("end", end_values)):
        posed = [frame.mesh_to_method(m) for m in twin.posed_meshes(values)]
        d = gt_dir / name
        atomic_write_bytes(d / f"{name}_rotate.ply", _ply(_concat(posed)))
        atomic_write_bytes(d / f"{name}_static_rotate.ply", _ply(_concat([posed[i] for i in static])))
        for i, grp in enumerate(moving):
            suffix = "" if single else f"_{i}"
            atomic_write_bytes(d / f"{name}_dynamic{suffix}_rotate.ply", _ply(_concat([posed[p] for p in grp])))
    return trans
