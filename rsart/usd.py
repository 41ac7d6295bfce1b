"""USD twins: write a :class:`~rsart.kinematics.Twin` as UsdPhysics USD and read USD articulations back.

Public API (the writer lives in :mod:`rsart.usd_write`, the articulation reader in
:mod:`rsart.usd_read` and the reading of geometry prims — meshes, gprims, UVs, textures, display
colours — into trimeshes in :mod:`rsart.usd_geometry`; this module is the face that names them):

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

from pathlib import Path

from .kinematics import Twin
from .usd_geometry import AXIS_VECTORS, Y_UP_TO_Z_UP, body_meshes, custom_attr, matrix_from_quat  # noqa: F401
from .usd_write import RSART_USD_FORMAT, prim_name, quat_from_matrix, rotation_x_to  # noqa: F401


def write_usd(twin: Twin, path: str | Path, *, units: str = "m",
              texture_files: dict[int, list[str]] | None = None, object_info: dict | None = None) -> None:
    """Write ``twin`` as a UsdPhysics articulation in a ``.usda`` file, atomically.

    ``units``: "m" or "scene" (both written with ``metersPerUnit`` 1; recorded in the layer's
    ``customLayerData["rsart:units"]``). ``texture_files``: optional part index -> one texture file
    per visual of that part, relative to the ``.usda``'s folder (absolute paths are made relative);
    textured visuals without an entry get their image written to ``textures/<part>_<k>.png``
    beside the ``.usda``. ``object_info`` (object_id, category, units, source) is kept as JSON in
    ``customLayerData["rsart:object"]`` so converting the file back keeps them.
    """
    from .usd_write import write_usd as _write

    _write(twin, path, units=units, texture_files=texture_files, object_info=object_info)


def read_usd(path: str | Path) -> Twin:
    """Read a USD articulation (rsart's own layout or a foreign one) as a Twin in metres, Z-up.

    Raises :class:`~rsart.errors.RsartError` (a :class:`~rsart.errors.ValidationError` listing every
    problem with its prim path) on unreadable or invalid input; never another exception type.
    """
    from .usd_read import read_usd as _read

    return _read(path)
