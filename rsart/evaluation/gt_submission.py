"""Reference submissions: the ground truth itself, or the ground truth perturbed by known amounts.

``make_gt_submission`` writes a valid ``rsart-submission/1`` folder: ``submission.json`` plus, per object
and state, the posed true part meshes (``<object>/<state>/<part>.ply``) and the true joints (axis/origin
at the ``start`` state, values of every state). Scored, it gives exactly 0 on the joint metrics and the
sampling floor on Chamfer. With a :class:`Perturbation` the *joints* are perturbed (meshes stay true):

* ``axis=A``  — every axis tilted by exactly A degrees about a seeded random perpendicular direction;
* ``pivot=P`` — every origin moved by P scene units perpendicular to both the true and the tilted axis
  (Axis Pos of revolute joints = 10·P);
* ``motion=M`` — every revolute Δv increased by M degrees; ``travel=T`` — every prismatic Δv by T units.

``expected_errors.json`` beside it lists the analytic errors per part, from closed forms independent of
:mod:`rsart.metrics` (quaternion product for the revolute Part Motion).
"""
from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import trimesh

from .. import __version__
from ..errors import RsartError
from ..io import atomic_dir, atomic_write_bytes, write_json
from ..kinematics import rotation_matrix
from ..metrics.chamfer import stable_seed
from ..twin_io import read_twin
from .ground_truth import GroundTruth, resolve_states
from .submission import FORMAT, STATIC


@dataclass(frozen=True)
class Perturbation:
    """Known joint errors: ``axis_deg`` tilt (°), ``pivot`` shift (scene units), ``motion_deg`` added to
    revolute Δv (°), ``travel`` added to prismatic Δv (units); ``seed`` picks the directions."""

    axis_deg: float = 0.0
    pivot: float = 0.0
    motion_deg: float = 0.0
    travel: float = 0.0
    seed: int = 0


def parse_perturbation(spec: str) -> Perturbation:
    """Parse ``axis=5deg,pivot=0.02,motion=3deg,travel=0.01,seed=0`` (units: deg suffix optional)."""
    keys = {"axis": "axis_deg", "pivot": "pivot", "motion": "motion_deg", "travel": "travel", "seed": "seed"}
    kw: dict[str, float | int] = {}
    for tok in filter(None, (t.strip() for t in spec.split(","))):
        if "=" not in tok:
            raise RsartError(f"--perturb-joints: {tok!r} is not key=value (keys: {', '.join(keys)})")
        k, v = (x.strip() for x in tok.split("=", 1))
        if k not in keys:
            raise RsartError(f"--perturb-joints: unknown key {k!r} (keys: {', '.join(keys)})")
        v = v[:-3] if v.endswith("deg") else v
        try:
            x = float(v)
        except ValueError:
            raise RsartError(f"--perturb-joints: {k}={v!r} is not a number") from None
        if not math.isfinite(x) or (k != "seed" and x < 0):
            raise RsartError(f"--perturb-joints: {k} must be a finite non-negative number")
        kw[keys[k]] = int(x) if k == "seed" else x
    return Perturbation(**kw)


def _perpendicular(a: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    while True:
        v = rng.normal(size=3)
        v -= np.dot(v, a) * a
        n = np.linalg.norm(v)
        if n > 1e-6:
            return v / n


def perturb_joint(jtype: str, axis: np.ndarray, origin: np.ndarray, delta: float, pert: Perturbation,
                  key: tuple) -> tuple[np.ndarray, np.ndarray, float, dict]:
    """(axis', origin', Δv', expected errors) of one true joint (axis unit, world frame at start)."""
    rng = np.random.default_rng(stable_seed(pert.seed, *key))
    a = np.asarray(axis, dtype=np.float64)
    alpha = math.radians(pert.axis_deg)
    a2 = rotation_matrix(_perpendicular(a, rng), alpha) @ a if alpha > 0 else a.copy()
    n = np.cross(a, a2)
    shift_dir = n / np.linalg.norm(n) if np.linalg.norm(n) > 1e-9 else _perpendicular(a, rng)
    o2 = np.asarray(origin, dtype=np.float64) + pert.pivot * shift_dir
    if jtype == "revolute":
        d2 = delta + math.radians(pert.motion_deg)
        # geodesic between Rot(a2, d2) and Rot(a, delta) from the unit-quaternion dot product
        c = math.cos(d2 / 2) * math.cos(delta / 2) + math.sin(d2 / 2) * math.sin(delta / 2) * math.cos(alpha)
        motion = math.degrees(2 * math.acos(min(1.0, abs(c))))
        expected = {"axis_ang": pert.axis_deg, "axis_pos": 10 * pert.pivot, "part_motion": motion}
    else:
        d2 = delta + pert.travel
        motion = math.sqrt(max(0.0, d2 * d2 + delta * delta - 2 * d2 * delta * math.cos(alpha)))
        expected = {"axis_ang": pert.axis_deg, "axis_pos": None, "part_motion": motion}
    return a2, o2, d2, expected


def make_gt_submission(gt: GroundTruth, out: str | os.PathLike, states: str = "start,end",
                       perturbation: Perturbation | None = None, overwrite: bool = False) -> Path:
    """Write the ground truth (optionally perturbed) as a submission folder at ``out``; returns submission.json."""
    out = Path(out)
    results, expected = {}, {}
    with atomic_dir(out, overwrite=overwrite) as tmp:
        for oid, (folder, meta) in gt.objects.items():
            twin = read_twin(folder, meta, visuals=False)
            sids = resolve_states(meta, states)
            start, end = meta.eval_states["start"], meta.eval_states["end"]
            names = {0: STATIC}
            for p in meta.parts[1:]:
                names[p.index] = p.name if p.name != STATIC else f"{p.name}_{p.index}"
            parts = {names[i]: {"meshes": {}} for i in names}
            for sid in sids:
                posed = twin.posed_meshes(meta.state(sid).values)
                for i, m in enumerate(posed):
                    rel = f"{oid}/{sid}/{names[i]}.ply"
                    geom = trimesh.Trimesh(m.vertices, m.faces, process=False)
                    atomic_write_bytes(tmp / rel, trimesh.exchange.ply.export_ply(geom, encoding="binary"))
                    parts[names[i]]["meshes"][sid] = rel
            axes = twin.posed_axes(meta.state(start).values)
            exp_obj = {}
            for p in meta.parts[1:]:
                j = twin.joint_of_part(p.index)
                o, a = axes[j.name]
                values = {s.id: float(s.values[j.name]) for s in meta.states}
                if perturbation is not None:
                    delta = values[end] - values[start]
                    a, o, d2, exp = perturb_joint(j.type, a, o, delta, perturbation, (oid, j.name))
                    values = {sid: v if sid != end else values[start] + d2 for sid, v in values.items()}
                    exp_obj[names[p.index]] = {"part": p.index, **exp}
                parts[names[p.index]]["joint"] = {"type": j.type, "axis": [float(x) for x in a],
                                                  "origin": [float(x) for x in o], "values": values}
            results[oid] = {"parts": parts}
            if perturbation is not None:
                expected[oid] = exp_obj
        method = {"name": "ground-truth" if perturbation is None else "ground-truth-perturbed",
                  "version": __version__, "inputs": ["ground-truth"], "camera_poses": "gt"}
        if perturbation is not None:
            method["perturbation"] = asdict(perturbation)
            write_json(tmp / "expected_errors.json", {"perturbation": asdict(perturbation), "objects": expected})
        dataset = {k: v for k, v in (("name", gt.name), ("version", gt.version)) if v is not None}
        write_json(tmp / "submission.json", {"format": FORMAT, "method": method, "dataset": dataset,
                                              "results": results})
    return out / "submission.json"
