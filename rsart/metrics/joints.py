"""Joint metrics of the literature: Axis Ang, Axis Pos, Part Motion (DESIGN.md §6.3).

All inputs in the same frame (the object's world frame at the ``start`` state) and scene units;
angles in radians in, degrees out (as the papers print them).

* Axis Ang (°): ``degrees(arccos(clip(|cos|, 0, 1)))`` — sign-invariant, 0–90°, never NaN
  (evaluated as ``atan2(|a×b|, |a·b|)``, the same value without arccos's rounding floor).
* Axis Pos (×10 scene units): shortest distance between the two axis lines; point-to-line when
  ``|d1 × d2| < 1e-6`` (parallel). Revolute joints only (prismatic → ``None``).
* Part Motion: revolute — geodesic angle (°) between ``Rot(a_pred, Δv_pred)`` and ``Rot(a, Δv)``;
  prismatic — ``‖Δv_pred·a_pred − Δv·a‖`` in scene units. The *true* type decides the reading.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kinematics import rotation_matrix

PARALLEL_EPS = 1e-6
AXIS_POS_SCALE = 10.0


@dataclass(frozen=True)
class JointEstimate:
    """A joint as the metrics see it: ``type`` revolute|prismatic, unit ``axis`` (3,), ``origin`` (3,) a point
    on the axis, ``delta`` = value[end] − value[start] (rad or scene units). World frame at the start state."""

    type: str
    axis: np.ndarray
    origin: np.ndarray
    delta: float

    @staticmethod
    def make(type: str, axis, origin, delta: float) -> "JointEstimate":
        """Normalise ``axis`` (raises ValueError on a zero or non-finite vector)."""
        a = np.asarray(axis, dtype=np.float64).reshape(3)
        n = float(np.linalg.norm(a))
        if not np.all(np.isfinite(a)) or n < 1e-12:
            raise ValueError(f"axis {a.tolist()} is zero or not finite")
        o = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64).reshape(3)
        return JointEstimate(type, a / n, o, float(delta))


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64).reshape(3)
    return v / np.linalg.norm(v)


def axis_angle_deg(a, b) -> float:
    """Angle (°) between the *lines* spanned by ``a`` and ``b`` (any non-zero length): 0–90°.

    Equals ``degrees(arccos(clip(|cos|, 0, 1)))``; computed as ``atan2(|a×b|, |a·b|)``, which has no
    rounding floor near 0° (arccos of a cosine rounded to 1 − 1e-16 would report ~1e-6°).
    """
    ua, ub = _unit(a), _unit(b)
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(ua, ub))), abs(float(np.dot(ua, ub)))))


def line_distance(o1, d1, o2, d2) -> float:
    """Shortest distance between the line through ``o1`` along ``d1`` and the line through ``o2`` along ``d2``.

    Skew/intersecting: ``|n·(o1−o2)|/|n|`` with ``n = d1 × d2``; parallel (``|n| < 1e-6`` for unit
    directions): distance from ``o1`` to the second line, ``|(o1 − o2) × d2|``.
    """
    u1, u2 = _unit(d1), _unit(d2)
    w = np.asarray(o1, dtype=np.float64) - np.asarray(o2, dtype=np.float64)
    n = np.cross(u1, u2)
    nn = float(np.linalg.norm(n))
    if nn < PARALLEL_EPS:
        return float(np.linalg.norm(np.cross(w, u2)))
    return abs(float(np.dot(n, w))) / nn


def axis_position(o_pred, d_pred, o_true, d_true) -> float:
    """Axis Pos: :func:`line_distance` ×10 (units of 0.1 scene unit, i.e. decimetres for metres)."""
    return AXIS_POS_SCALE * line_distance(o_pred, d_pred, o_true, d_true)


def rotation_geodesic_deg(R1: np.ndarray, R2: np.ndarray) -> float:
    """Geodesic angle (°) between rotations (3, 3): the angle of ``R1 R2ᵀ``.

    Equals ``arccos(clip((tr(R1 R2ᵀ) − 1)/2, −1, 1))``; computed from the quaternion of ``R1 R2ᵀ``
    (scipy, ``2·atan2(|q_xyz|, |q_w|)``), which stays exact near 0° where the trace form loses ~1e-6°.
    """
    from scipy.spatial.transform import Rotation

    return math.degrees(float(Rotation.from_matrix(np.asarray(R1) @ np.asarray(R2).T).magnitude()))


def part_motion(true_type: str, axis_pred, delta_pred: float, axis_true, delta_true: float) -> float:
    """Part Motion of one joint, read with the *true* type: revolute → degrees, prismatic → scene units."""
    if true_type == "revolute":
        return rotation_geodesic_deg(rotation_matrix(_unit(axis_pred), delta_pred),
                                     rotation_matrix(_unit(axis_true), delta_true))
    if true_type == "prismatic":
        return float(np.linalg.norm(delta_pred * _unit(axis_pred) - delta_true * _unit(axis_true)))
    raise ValueError(f"unknown joint type {true_type!r}")


def joint_errors(pred: JointEstimate, true: JointEstimate) -> dict[str, float | None]:
    """All joint metrics of one predicted/true pair.

    Returns ``axis_ang`` (°), ``axis_pos`` (×10 units; ``None`` for a prismatic true joint),
    ``part_motion`` (° or units, by the true type), ``type_correct`` (1.0 or 0.0).
    """
    return {
        "axis_ang": axis_angle_deg(pred.axis, true.axis),
        "axis_pos": axis_position(pred.origin, pred.axis, true.origin, true.axis) if true.type == "revolute" else None,
        "part_motion": part_motion(true.type, pred.axis, pred.delta, true.axis, true.delta),
        "type_correct": 1.0 if pred.type == true.type else 0.0,
    }
