"""Merge per-joint runs of a single-joint method (PARIS, ArticulatedGS) into one submission entry.

The paper ran these methods once per movable joint (that joint moving, the others fixed) and merged
the outputs for evaluation; it does not say how. This adapter merges as follows (all in rsart's world,
at the ``start`` state of eval_states, where every run's start state coincides):

* movable part k: its joint = run k's joint; its start mesh = run k's dynamic mesh without the faces
  that lie on the dynamic meshes of runs of k's descendants (in run k those moved with k);
* the static part: the static mesh of the first run with a static mesh, without the faces that lie on
  any other run's dynamic mesh (in that run the other movable parts were static);
* end-state meshes: each part's start mesh moved by the composed predicted motions along its chain,
  ``T_k = T_parent(k) · M_k`` (M = start->end motion of a joint, expressed at the start state);
* joint values: ``{start: 0, end: Δ·r}``, Δ the run's min->max motion and r = (v_end − v_start) /
  (max − min) from meta.json (1 for the RS-Art protocol, whose start/end are the joints' limits).

"Lies on" = all three vertices within ``eps`` (default 1% of the static mesh's bounding-box diagonal).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from rsart.format import ObjectMeta

from .geometry import joint_to_motion, remove_near
from .states import joint_range
from .submission_io import STATIC, PartOut


@dataclass
class JointRun:
    """A single-joint run read in rsart's world: the joint's start->end motion and optional meshes."""

    type: str
    axis: np.ndarray
    origin: np.ndarray
    delta: float
    static: trimesh.Trimesh | None = None
    dynamic: trimesh.Trimesh | None = None  # start state
    source: str = ""


def _descendants(meta: ObjectMeta, part: int) -> list[int]:
    out = []
    for j in meta.joints:
        if j.parent == part:
            out += [j.child] + _descendants(meta, j.child)
    return out


def part_names(meta: ObjectMeta) -> dict[int, str]:
    """Submission part names: "static" for part 0, the true part names otherwise (renamed if "static")."""
    names = {0: STATIC}
    for p in meta.parts[1:]:
        names[p.index] = p.name if p.name != STATIC else f"{p.name}_{p.index}"
    return names


def _scaled_delta(meta: ObjectMeta, joint: str, r: JointRun, notes: list[str]) -> float:
    """Δ of a min->max run rescaled to the eval start->end span of that joint."""
    j = meta.joint(joint)
    lo, hi = joint_range(meta, j)
    v0 = meta.state(meta.eval_states["start"]).values[joint]
    v1 = meta.state(meta.eval_states["end"]).values[joint]
    ratio = (v1 - v0) / (hi - lo) if hi > lo else 1.0
    if abs(ratio - 1.0) > 1e-9:
        notes.append(f"{joint}: eval start->end spans {ratio:.4g} of the min->max motion; Δ scaled by it")
    return float(r.delta * ratio)


def merge_runs(meta: ObjectMeta, runs: dict[str, JointRun], eps_fraction: float = 0.01) -> tuple[list[PartOut], list[str]]:
    """Parts of the merged entry (static first) and notes; ``runs`` maps joint name -> JointRun."""
    start, end = meta.eval_states["start"], meta.eval_states["end"]
    names = part_names(meta)
    notes: list[str] = []
    by_child = {j.child: j for j in meta.joints}
    run_of = {j.child: runs.get(j.name) for j in meta.joints}
    missing = [j.name for j in meta.joints if j.name not in runs]
    if missing:
        notes.append(f"no run for joints {missing}: their parts are left out (scored as failures)")
    statics = [r.static for r in runs.values() if r.static is not None and len(r.static.faces)]
    eps = 0.0
    if statics:
        eps = eps_fraction * float(np.linalg.norm(np.ptp(statics[0].vertices, axis=0)))
    # start meshes
    start_mesh: dict[int, trimesh.Trimesh | None] = {}
    if statics:
        first = next(n for n, r in runs.items() if r.static is not None and len(r.static.faces))
        others = [r.dynamic for n, r in runs.items() if n != first]
        start_mesh[0] = remove_near(statics[0], others, eps)
        notes.append(f"static part: run {first!r}'s static mesh minus the other runs' moving parts (eps {eps:.4g})")
    for child, r in run_of.items():
        if r is None or r.dynamic is None:
            continue
        below = [run_of[d].dynamic for d in _descendants(meta, child) if run_of.get(d) is not None]
        start_mesh[child] = remove_near(r.dynamic, below, eps) if below else r.dynamic
    scaled = {j.child: _scaled_delta(meta, j.name, runs[j.name], notes) for j in meta.joints if j.name in runs}
    # end poses from composed motions
    T_end: dict[int, np.ndarray] = {0: np.eye(4)}

    def pose(p: int) -> np.ndarray:
        if p not in T_end:
            j = by_child[p]
            r = run_of[p]
            M = joint_to_motion(r.type, r.axis, r.origin, scaled[p]) if r is not None else np.eye(4)
            T_end[p] = pose(j.parent) @ M
        return T_end[p]

    parts = [PartOut(STATIC, {})]
    if start_mesh.get(0) is not None:
        parts[0].meshes = {start: start_mesh[0], end: start_mesh[0]}
    for j in sorted(meta.joints, key=lambda j: j.child):
        r = runs.get(j.name)
        if r is None:
            continue
        part = PartOut(names[j.child], {}, {"type": r.type, "axis": r.axis, "origin": r.origin,
                                            "values": {start: 0.0, end: scaled[j.child]}})
        m = start_mesh.get(j.child)
        if m is not None and len(m.faces):
            me = m.copy()
            me.apply_transform(pose(j.child))
            part.meshes = {start: m, end: me}
        parts.append(part)
        notes.append(f"{j.name}: {r.type} Δ={r.delta:.6g} from {r.source}")
    return parts, notes
