"""Physical sanity checks of a twin: part clearances and interpenetration at given joint values.

Exact, not sampled: posed part meshes become manifold3d solids; the clearance of two parts is
``Manifold.min_gap`` (0 when they touch or overlap) and the overlap is the volume of their
boolean intersection. Units: metres (volumes m³).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...kinematics import Twin
from ...states import multi_values, protocol_states
from . import shapes


@dataclass(frozen=True)
class Contact:
    """Parts ``a`` < ``b`` closer than the required clearance: ``gap`` (m) and overlap ``volume`` (m³)."""

    a: str
    b: str
    gap: float
    volume: float


def contacts(twin: Twin, values: dict[str, float], clearance: float = 0.001) -> list[Contact]:
    """Pairs of parts whose gap is below ``clearance`` metres at joint ``values``."""
    meshes = twin.posed_meshes(values)
    solids = [shapes.from_trimesh(m) for m in meshes]
    out = []
    for i in range(len(meshes)):
        for j in range(i + 1, len(meshes)):
            lo = np.maximum(meshes[i].bounds[0], meshes[j].bounds[0])
            hi = np.minimum(meshes[i].bounds[1], meshes[j].bounds[1])
            if np.any(lo > hi + clearance):
                continue                                            # bounding boxes are apart
            gap = solids[i].min_gap(solids[j], clearance * 2)
            if gap < clearance:
                vol = (solids[i] ^ solids[j]).volume()
                out.append(Contact(twin.parts[i].name, twin.parts[j].name, float(gap), float(vol)))
    return out


def check_states(twin: Twin, steps: int = 12) -> list[dict[str, float]]:
    """The joint configurations to check: the RS-Art protocol states, the multi-part motion at every
    1/``steps`` of the ranges, and each joint alone at 1/4, 1/2, 3/4 of its range (others at m0)."""
    states, _ = protocol_states(twin.joints)
    vals = [s.values for s in states]
    vals += [multi_values(twin.joints, k / steps) for k in range(1, steps) if k * 3 % steps]
    base = multi_values(twin.joints, 0.0)
    for j in twin.joints:
        lo, hi = (j.limits if j.limits is not None else (0.0, np.pi / 2))
        for t in (0.25, 0.5, 0.75):
            v = dict(base)
            v[j.name] = lo + t * (hi - lo)
            vals.append(v)
    return vals


def clearance_report(twin: Twin, clearance: float = 0.001) -> list[tuple[dict[str, float], Contact]]:
    """Every (configuration, contact) found over :func:`check_states`; empty = the twin is clean."""
    out = []
    for v in check_states(twin):
        out.extend((v, c) for c in contacts(twin, v, clearance))
    return out


def lowest_point(twin: Twin, values: dict[str, float]) -> float:
    """Minimum z of the posed object (the base rests on z = 0; nothing should go below it)."""
    return float(twin.bounds(values)[0, 2])
