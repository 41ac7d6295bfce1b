"""USD twins: write a :class:`~rsart.kinematics.Twin` as UsdPhysics USD and read USD articulations back.

Public API (the implementation lives in :mod:`rsart.usd_write` and :mod:`rsart.usd_read`):

* :func:`write_usd` — rsart's own USD layout (``.usda`` text): Z-up stage, ``metersPerUnit`` 1,
  one rigid-body ``Xform`` per part (translated to the part's bounding-box centre, double
  precision) holding a ``geometry`` mesh (+ textured ``visuals``), UsdPhysics revolute/prismatic
  joints (revolute limits in degrees), an articulation root and a fixed joint anchoring the base
  to the world. rsart also stores double-precision ``rsart:*`` attributes beside the float ones
  UsdPhysics defines, so a round trip is exact to ~1e-12 m.
* :func:`read_usd` — reads rsart's layout *and* articulations authored by other tools (Isaac Sim
  style): rigid bodies with nested/instanced meshes under arbitrary transforms, joints in any
  joint frame, Y-up stages (rotated into rsart's Z-up world by +90° about X) and any
  ``metersPerUnit`` (scaled to metres). See docs/usd.md.

Frames: rsart world = object base frame at rest (all joint values 0), Z up, metres.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from .kinematics import Twin

RSART_USD_FORMAT = "rsart-usd/1"
_IDENT = re.compile(r"[^A-Za-z0-9_]")

# Rotation taking a Y-up stage into rsart's Z-up world (+90 deg about X): (x, y, z) -> (x, -z, y).
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
AXIS_VECTORS = {"X": np.array([1.0, 0.0, 0.0]), "Y": np.array([0.0, 1.0, 0.0]), "Z": np.array([0.0, 0.0, 1.0])}


def prim_name(name: str, taken: set[str]) -> str:
    """A valid, unique USD prim name for ``name`` (invalid characters -> '_', leading digit prefixed)."""
    base = _IDENT.sub("_", name) or "_"
    if base[0].isdigit():
        base = "_" + base
    out, k = base, 1
    while out in taken:
        out = f"{base}_{k}"
        k += 1
    taken.add(out)
    return out


def quat_from_matrix(R: np.ndarray) -> tuple[float, float, float, float]:
    """(w, x, y, z) unit quaternion of a (3, 3) rotation matrix (scipy, scalar-last -> scalar-first)."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_quat()
    return float(w), float(x), float(y), float(z)


def matrix_from_quat(w: float, x: float, y: float, z: float) -> np.ndarray:
    """(3, 3) rotation of a unit quaternion given scalar-first."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat([x, y, z, w]).as_matrix()


def rotation_x_to(axis: np.ndarray) -> np.ndarray:
    """(3, 3) the smallest rotation taking +X onto the unit ``axis`` (the joint frame rsart writes)."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    x = np.array([1.0, 0.0, 0.0])
    c = float(np.dot(x, a))
    if c < -1.0 + 1e-12:  # opposite: half turn about Z
        return np.diag([-1.0, -1.0, 1.0])
    v = np.cross(x, a)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + (K @ K) / (1.0 + c)


def deg(rad: float) -> float:
    return math.degrees(rad)


def write_usd(twin: Twin, path: str | Path, *, units: str = "m",
              texture_files: dict[int, list[str]] | None = None) -> None:
    """Write ``twin`` as a UsdPhysics articulation in a ``.usda`` file, atomically.

    ``units``: "m" or "scene" (both written with ``metersPerUnit`` 1; recorded in the layer's
    ``customLayerData["rsart:units"]``). ``texture_files``: optional part index -> one texture file
    per visual of that part, relative to the ``.usda``'s folder (absolute paths are made relative);
    textured visuals without an entry get their image written to ``textures/<part>_<k>.png``
    beside the ``.usda``.
    """
    from .usd_write import write_usd as _write

    _write(twin, path, units=units, texture_files=texture_files)


def read_usd(path: str | Path) -> Twin:
    """Read a USD articulation (rsart's own layout or a foreign one) as a Twin in metres, Z-up.

    Raises :class:`~rsart.errors.RsartError` (a :class:`~rsart.errors.ValidationError` listing every
    problem with its prim path) on unreadable or invalid input; never another exception type.
    """
    from .usd_read import read_usd as _read

    return _read(path)
