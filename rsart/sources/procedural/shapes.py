"""Watertight solid primitives for procedural twins, built on manifold3d.

Every function returns a ``manifold3d.Manifold`` (a closed, oriented 2-manifold solid), so
unions and differences of them stay watertight; :func:`to_trimesh` converts the result.
Units: metres; frame: the object's world frame (z up). Angles in radians.

manifold3d does the constructive solid geometry (robust booleans with guaranteed manifold
output); the helpers here only place primitives and convert meshes.
"""
from __future__ import annotations

from typing import Sequence

import manifold3d as mf
import numpy as np
import trimesh

Solid = mf.Manifold
Vec = Sequence[float]

SEGMENTS = 24  # circle resolution: keeps objects well under ~20k triangles


def _affine(T: np.ndarray) -> np.ndarray:
    """(4, 4) -> the (3, 4) matrix manifold3d expects."""
    return np.ascontiguousarray(np.asarray(T, dtype=np.float64)[:3, :4])


def transform(s: Solid, T: np.ndarray) -> Solid:
    """Apply a (4, 4) rigid/affine transform."""
    return s.transform(_affine(T))


def align_z(axis: Vec) -> np.ndarray:
    """(4, 4) rotation taking +z to the unit ``axis``."""
    a = np.asarray(axis, dtype=np.float64)
    return trimesh.geometry.align_vectors([0.0, 0.0, 1.0], a / np.linalg.norm(a))


def box(size: Vec, center: Vec = (0, 0, 0)) -> Solid:
    """Axis-aligned box of ``size`` (sx, sy, sz) centred at ``center``."""
    return mf.Manifold.cube(tuple(float(x) for x in size), center=True).translate(tuple(float(x) for x in center))


def box_between(lo: Vec, hi: Vec) -> Solid:
    """Axis-aligned box spanning corners ``lo`` and ``hi``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return box(hi - lo, (lo + hi) / 2)


def cylinder(radius: float, length: float, center: Vec = (0, 0, 0), axis: Vec = (0, 0, 1),
             segments: int = SEGMENTS, radius_top: float | None = None) -> Solid:
    """Cylinder (or cone frustum with ``radius_top``) of ``length`` along ``axis``, centred at ``center``."""
    c = mf.Manifold.cylinder(float(length), float(radius), float(radius if radius_top is None else radius_top),
                             segments, True)
    T = align_z(axis)
    T[:3, 3] = center
    return transform(c, T)


def rod(p0: Vec, p1: Vec, radius: float, segments: int = 12) -> Solid:
    """Cylinder of ``radius`` from point ``p0`` to point ``p1``."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    return cylinder(radius, float(np.linalg.norm(d)), (p0 + p1) / 2, d, segments)


def bar(p0: Vec, p1: Vec, width: float, height: float, up: Vec = (0, 0, 1)) -> Solid:
    """Rectangular bar from ``p0`` to ``p1`` (cross-section ``width`` x ``height``, ``height`` along ``up``)."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    L = float(np.linalg.norm(d))
    x = d / L
    z = np.asarray(up, float) - np.dot(up, x) * x
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, (p0 + p1) / 2
    return transform(box((L, width, height)), T)


def sphere(radius: float, center: Vec = (0, 0, 0), segments: int = SEGMENTS) -> Solid:
    return mf.Manifold.sphere(float(radius), segments).translate(tuple(float(x) for x in center))


def torus(major: float, minor: float, center: Vec = (0, 0, 0), axis: Vec = (0, 0, 1),
          degrees: float = 360.0, start_deg: float = 0.0, segments: int = SEGMENTS, tube_segments: int = 12,
          plane: tuple[Vec, Vec] | None = None) -> Solid:
    """Torus (or a ``degrees`` arc of one starting at ``start_deg``) around ``axis`` through ``center``.

    The arc starts on the local +x direction and turns counter-clockwise towards local +y; pass
    ``plane=(x_dir, y_dir)`` (orthonormal world directions) to fix them (``axis`` is then x_dir × y_dir).
    """
    circle = mf.CrossSection.circle(float(minor), tube_segments).translate((float(major), 0.0))
    n = max(3, int(round(segments * degrees / 360.0)))
    t = circle.revolve(n, float(degrees))
    if start_deg:
        t = t.rotate((0.0, 0.0, float(start_deg)))
    if plane is not None:
        x, y = np.asarray(plane[0], float), np.asarray(plane[1], float)
        T = np.eye(4)
        T[:3, 0], T[:3, 1], T[:3, 2] = x, y, np.cross(x, y)
    else:
        T = align_z(axis)
    T[:3, 3] = center
    return transform(t, T)


def extrude(polygon: np.ndarray, height: float, T: np.ndarray | None = None, holes: Sequence[np.ndarray] = (),
            scale_top: tuple[float, float] = (1.0, 1.0)) -> Solid:
    """Extrude a 2-D ``polygon`` (N, 2) (with optional hole polygons) by ``height`` along local +z, then apply ``T``."""
    contours = [np.asarray(polygon, float)] + [np.asarray(h, float)[::-1] for h in holes]
    cs = mf.CrossSection(contours, mf.FillRule.EvenOdd)
    s = cs.extrude(float(height), 0, 0.0, scale_top)
    return transform(s, T) if T is not None else s


def rounded_rect(w: float, h: float, r: float, segments: int = 6) -> np.ndarray:
    """(N, 2) counter-clockwise outline of a ``w`` x ``h`` rectangle with corner radius ``r``, centred at 0."""
    r = min(r, w / 2 - 1e-6, h / 2 - 1e-6)
    pts = []
    for cx, cy, a0 in ((w / 2 - r, h / 2 - r, 0), (-w / 2 + r, h / 2 - r, 90), (-w / 2 + r, -h / 2 + r, 180),
                       (w / 2 - r, -h / 2 + r, 270)):
        for k in range(segments + 1):
            a = np.radians(a0 + 90.0 * k / segments)
            pts.append((cx + r * np.cos(a), cy + r * np.sin(a)))
    return np.asarray(pts)


def ellipse(a: float, b: float, n: int = 32) -> np.ndarray:
    """(n, 2) counter-clockwise ellipse with half-axes ``a`` (x) and ``b`` (y)."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([a * np.cos(t), b * np.sin(t)], axis=1)


def open_box(lo: Vec, hi: Vec, wall: float, open_side: str) -> Solid:
    """A hollow box (walls of thickness ``wall``) spanning ``lo``..``hi`` with one face open.

    ``open_side`` is one of "+x", "-x", "+y", "-y", "+z", "-z".
    """
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    ilo, ihi = lo + wall, hi - wall
    ax = "xyz".index(open_side[1])
    if open_side[0] == "+":
        ihi[ax] = hi[ax] + wall
    else:
        ilo[ax] = lo[ax] - wall
    return box_between(lo, hi) - box_between(ilo, ihi)


def union(solids: Sequence[Solid]) -> Solid:
    """Boolean union of ``solids`` (watertight result)."""
    solids = [s for s in solids if not s.is_empty()]
    if not solids:
        return mf.Manifold()
    return mf.Manifold.batch_boolean(list(solids), mf.OpType.Add)


def subtract(solid: Solid, cutters: Sequence[Solid]) -> Solid:
    """``solid`` minus every cutter."""
    if not cutters:
        return solid
    return mf.Manifold.batch_boolean([solid, *cutters], mf.OpType.Subtract)


def to_trimesh(s: Solid) -> trimesh.Trimesh:
    """Convert a solid to a trimesh (float64 vertices, outward-facing triangles, no processing)."""
    m = s.to_mesh64()
    v = np.asarray(m.vert_properties, dtype=np.float64)[:, :3]
    f = np.asarray(m.tri_verts, dtype=np.int64)
    return trimesh.Trimesh(v, f, process=False)


def from_trimesh(mesh: trimesh.Trimesh) -> Solid:
    """A watertight trimesh as a manifold3d solid (used for intersection checks)."""
    m = mf.Mesh64(vert_properties=np.array(mesh.vertices, dtype=np.float64, order="C", subok=False),
                  tri_verts=np.array(mesh.faces, dtype=np.uint64, order="C", subok=False))
    return mf.Manifold(m)
