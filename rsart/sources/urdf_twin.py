"""Any URDF -> an RS-Art object folder (``rsart convert urdf``), and the steps PartNet-Mobility shares.

The pipeline, each step a small function:

1. :func:`rsart.urdf.read_urdf` (safe XML, fixed joints merged, ``continuous`` = revolute without limits,
   meshes resolved only inside the URDF's folder);
2. :func:`fold_helper_parts`: movable parts without geometry (helper links) cannot be evaluated, and the
   format gives every movable part exactly one joint. A helper with one child joint is folded into its
   child: the child keeps the *helper's* joint and the child's own joint is recorded in
   ``joint.extra["folded"]`` (a ``screw`` note when both joints share one axis line, e.g. PartNet's
   prismatic + continuous bottle caps). A helper without children is dropped (``extra["dropped"]``).
3. :func:`scale_twin` (optional unit conversion: geometry, joint origins and prismatic limits);
4. :func:`watertight_copy` per part: ``TwinPart.mesh`` becomes a watertight copy (for metrics), the
   original (textured) meshes stay as ``TwinPart.visuals`` (for rendering).

Watertight copies: a part whose merged mesh is already a closed, consistently wound surface is kept
exactly. Any other part (PartNet meshes are triangle soups with open sheets) is remeshed as the
``level``-offset surface of its unsigned distance field: exact point-to-triangle distances (open3d ray
casting) on a grid of spacing ``pitch`` in a narrow band around the surface, an isosurface at distance
``level`` (open3d flying edges), optional quadric decimation. The result is closed by construction; its
distance to the original surface is ``level`` (a thin sheet becomes a slab of thickness 2·level), so
the Chamfer it adds is about ``2000·level²`` — measured per part and recorded in ``part.extra``.
"""
from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from ..errors import RsartError
from ..format import Joint, ObjectMeta
from ..kinematics import Twin, TwinPart

class MissingTextureWarning(UserWarning):
    """A mesh's material references a texture image that is not there (the surface renders untextured)."""


#: two joints are "on one axis line" (a screw) within these tolerances (unit-direction difference, distance)
COLLINEAR_TOL = 1e-6


@dataclass(frozen=True)
class WatertightConfig:
    """How watertight copies are made. ``resolution``: grid cells across the *object's* bounding-box
    diagonal; ``part_resolution``: minimum cells across each *part's* diagonal (finer grids for small
    parts); ``level``: offset distance in grid cells; ``max_faces``: decimation target (0 = none);
    ``max_cells``: refuse grids larger than this (memory bound)."""

    resolution: int = 384
    part_resolution: int = 96
    level: float = 0.75
    max_faces: int = 100_000
    max_cells: int = 60_000_000
    chamfer_samples: int = 10_000

    def pitch(self, object_diag: float, part_diag: float) -> float:
        return min(object_diag / self.resolution, part_diag / self.part_resolution)


# ----------------------------------------------------------------------------- structure
def _is_empty(mesh: trimesh.Trimesh) -> bool:
    return len(mesh.faces) == 0


def _collinear(a: Joint, b: Joint) -> bool:
    """True when joints ``a`` and ``b`` share one axis line (direction up to sign, and position)."""
    da, db = np.asarray(a.axis, float), np.asarray(b.axis, float)
    if np.linalg.norm(np.cross(da, db)) > 1e-6:
        return False
    off = np.asarray(b.origin, float) - np.asarray(a.origin, float)
    return float(np.linalg.norm(np.cross(off, da))) < 1e-6 * max(1.0, float(np.linalg.norm(off)))


def _joint_record(j: Joint) -> dict[str, Any]:
    return {"name": j.name, "type": j.type, "axis": [float(x) for x in j.axis],
            "origin": [float(x) for x in j.origin],
            "limits": None if j.limits is None else [float(j.limits[0]), float(j.limits[1])], **j.extra}


def reindexed(name: str, parts: list[TwinPart], joints: list[Joint]) -> Twin:
    """A Twin from a subset of ``parts`` (base first) and joints, renumbered 0..n-1 in the given order."""
    new_index = {p.index: i for i, p in enumerate(parts)}
    new_parts = [TwinPart(i, p.name, p.mesh, p.visuals, dict(p.extra)) for i, p in enumerate(parts)]
    new_joints = [replace(j, parent=new_index[j.parent], child=new_index[j.child]) for j in joints]
    new_joints.sort(key=lambda j: j.child)
    return Twin(name, new_parts, new_joints)


def fold_helper_parts(twin: Twin, source: str | None = None) -> tuple[Twin, list[str]]:
    """Fold or drop movable parts without geometry (see module docstring); returns (twin, notes).

    Raises RsartError for a geometry-less part with several child joints (no one-joint representation).
    """
    notes: list[str] = []
    parts = {p.index: p for p in twin.parts}
    joints = {j.child: j for j in twin.joints}  # child part -> joint
    changed = True
    while changed:
        changed = False
        for pi in sorted(parts):
            p = parts[pi]
            if pi == 0 or not _is_empty(p.mesh):
                continue
            kids = [c for c, j in joints.items() if j.parent == pi]
            hj = joints[pi]
            if not kids:
                notes.append(f"part {p.name!r} has no geometry and no children: dropped with its joint {hj.name!r}")
                del parts[pi], joints[pi]
            elif len(kids) == 1:
                c = kids[0]
                cj = joints[c]
                kind = "screw" if _collinear(hj, cj) else "chain"
                folded = {"kind": kind, "helper_part": p.name, "helper_links": p.extra.get("links", []),
                          "kept": hj.name, "dropped": _joint_record(cj),
                          "note": ("the child also turns about this axis line (a screw/cylindrical pair); rsart "
                                   "keeps the helper's joint as the part's one joint and does not pose the "
                                   "dropped one" if kind == "screw" else
                                   "a two-joint chain through a link without geometry; the part keeps the "
                                   "first joint, the second is recorded but not posed")}
                extra = dict(hj.extra)
                extra["folded"] = folded
                joints[c] = replace(hj, child=c, extra=extra)
                notes.append(f"helper part {p.name!r} (no geometry) folded: part {parts[c].name!r} keeps joint "
                             f"{hj.name!r} ({hj.type}); joint {cj.name!r} ({cj.type}) recorded as {kind}")
                del parts[pi], joints[pi]
            else:
                raise RsartError(f"{source or twin.name}: part {p.name!r} (links {p.extra.get('links', [])}) has "
                                 f"no geometry but {len(kids)} child joints; it cannot be folded into a "
                                 "one-joint-per-part twin")
            changed = True
            break
    if not notes:
        return twin, notes
    ordered = [parts[i] for i in sorted(parts)]
    return reindexed(twin.name, ordered, list(joints.values())), notes


def check_geometry(twin: Twin, source: str) -> None:
    """Every part needs geometry (metrics sample it) and an object needs a movable part (its states move
    one); raise RsartError naming the empty parts or saying that nothing moves."""
    empty = [p.name for p in twin.parts if _is_empty(p.mesh)]
    if empty:
        raise RsartError(f"{source}: parts without any geometry: {empty} (every part needs a mesh to be evaluated)")
    for p in twin.parts:
        if not np.all(np.isfinite(p.mesh.vertices)):
            raise RsartError(f"{source}: part {p.name!r}: mesh has non-finite vertex coordinates")
        if not p.mesh.area > 0:
            raise RsartError(f"{source}: part {p.name!r}: mesh has no surface (zero area)")
    if not twin.joints:
        raise RsartError(f"{source}: no movable part with geometry (an RS-Art object needs at least one "
                         "revolute or prismatic joint whose child has a mesh)")


def scale_twin(twin: Twin, s: float) -> Twin:
    """The twin scaled by ``s`` about the world origin (meshes, visuals, joint origins, prismatic limits)."""
    if not (math.isfinite(s) and s > 0):
        raise RsartError(f"scale must be a positive finite number, got {s}")
    S = np.diag([s, s, s, 1.0])
    parts = []
    for p in twin.parts:
        m = p.mesh.copy()
        m.apply_transform(S)
        vis = [v.copy() for v in p.visuals]
        for v in vis:
            v.apply_transform(S)
        parts.append(TwinPart(p.index, p.name, m, vis, dict(p.extra)))
    joints = []
    for j in twin.joints:
        lim = j.limits
        if j.type == "prismatic" and lim is not None:
            lim = (lim[0] * s, lim[1] * s)
        joints.append(replace(j, origin=np.asarray(j.origin, float) * s, limits=lim))
    return Twin(twin.name, parts, joints)


# ----------------------------------------------------------------------------- watertight copies
def _closed_as_is(mesh: trimesh.Trimesh) -> trimesh.Trimesh | None:
    m = trimesh.Trimesh(mesh.vertices, mesh.faces, process=True)
    m.merge_vertices(merge_tex=True, merge_norm=True)
    m.update_faces(m.nondegenerate_faces())
    if len(m.faces) and m.is_watertight and m.is_winding_consistent and m.volume > 0:
        return m
    return None


def _udf_grid(mesh: trimesh.Trimesh, pitch: float, level: float, shift: float, max_cells: int):
    """Truncated unsigned distance (scene units) on a grid: returns (volume [i,j,k], grid origin (3,))."""
    import open3d as o3d
    from scipy import ndimage

    pad = 3
    lo = mesh.bounds[0] - (pad + 1) * pitch - level + shift * pitch
    hi = mesh.bounds[1] + (pad + 1) * pitch + level
    shape = np.ceil((hi - lo) / pitch).astype(int) + 1
    if int(np.prod(shape)) > max_cells:
        raise RsartError(f"watertight remesh grid {tuple(shape)} exceeds {max_cells} cells; lower the resolution")
    # narrow band: grid cells within two cells of dense surface samples; exact distances only there
    n = int(min(4e6, max(2e4, 4.0 * mesh.area / pitch ** 2)))
    pts, _ = trimesh.sample.sample_surface(mesh, n, seed=0)
    pts = np.vstack([pts, mesh.vertices])
    idx = np.clip(np.round((pts - lo) / pitch).astype(int), 0, shape - 1)
    band = np.zeros(shape, bool)
    band[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    band = ndimage.binary_dilation(band, iterations=2)
    far = 3.0 * pitch
    vol = np.full(shape, far, np.float32)
    cells = np.argwhere(band)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)),
                        o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    d = scene.compute_distance(o3d.core.Tensor((lo + cells * pitch).astype(np.float32))).numpy()
    vol[cells[:, 0], cells[:, 1], cells[:, 2]] = np.minimum(d, far)
    return vol, lo


def _isosurface(vol: np.ndarray, lo: np.ndarray, pitch: float, level: float) -> trimesh.Trimesh:
    import open3d as o3d

    # open3d indexes volumes [z, y, x] and puts voxel [z, y, x] at (x, y, z)
    iso = o3d.t.geometry.TriangleMesh.create_isosurfaces(
        o3d.core.Tensor(np.ascontiguousarray(vol.transpose(2, 1, 0))), [float(level)])
    v = iso.vertex.positions.numpy().astype(np.float64)
    f = iso.triangle.indices.numpy().astype(np.int64)
    m = trimesh.Trimesh(lo + v * pitch, f, process=True)
    m.merge_vertices()
    if len(m.faces) and m.volume < 0:
        m.invert()
    return m


def _closed(m: trimesh.Trimesh) -> bool:
    return bool(len(m.faces)) and m.is_watertight and m.is_winding_consistent


def _decimate(mesh: trimesh.Trimesh, max_faces: int) -> trimesh.Trimesh | None:
    """Quadric decimation to about ``max_faces`` that stays watertight, or None.

    fast-simplification (~1 s per million faces) is tried at decreasing aggressiveness (its default
    occasionally pinches two nearby sheets into a non-manifold edge; gentler settings do not on the
    PartNet samples); without it, open3d's decimation (~60x slower) is tried once.
    """
    try:
        import fast_simplification
    except ImportError:
        fast_simplification = None
    candidates = []
    if fast_simplification is not None:
        for agg in (3, 1):
            v, f = fast_simplification.simplify(mesh.vertices.astype(np.float32), mesh.faces.astype(np.int32),
                                                target_reduction=1.0 - max_faces / len(mesh.faces), agg=agg)
            # process=False: merging coincident vertices the decimator left apart can pinch the surface
            out = trimesh.Trimesh(np.asarray(v, np.float64), np.asarray(f), process=False)
            out.remove_unreferenced_vertices()
            candidates.append(out)
            if _closed(out):
                break
    else:
        import open3d as o3d

        om = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(mesh.vertices),
                                       o3d.utility.Vector3iVector(mesh.faces))
        d = om.simplify_quadric_decimation(int(max_faces))
        candidates.append(trimesh.Trimesh(np.asarray(d.vertices), np.asarray(d.triangles), process=False))
    for out in candidates:
        if _closed(out):
            if out.volume < 0:
                out.invert()
            return out
    return None


def _sampled_chamfer(a: trimesh.Trimesh, b: trimesh.Trimesh, n: int) -> tuple[float, float]:
    """(Chamfer(a, b), Chamfer(a, a) sampling floor), ×1000, one fixed seed each (DESIGN §6.3 distance)."""
    from ..metrics.chamfer import chamfer_distance, sample_surface

    pa, pa2, pb = sample_surface(a, n, 1), sample_surface(a, n, 2), sample_surface(b, n, 3)
    return chamfer_distance(pa, pb), chamfer_distance(pa, pa2)


def watertight_copy(mesh: trimesh.Trimesh, pitch: float, cfg: WatertightConfig = WatertightConfig()
                    ) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """A watertight copy of ``mesh`` (same frame and units) and a record of how it was made.

    Record keys: ``method`` ("closed-as-is" | "udf-offset"), ``watertight`` (bool), ``pitch``/``level``
    (scene units), ``faces``, ``chamfer_vs_original`` and ``chamfer_floor`` (×1000, 10k samples each).
    """
    src = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), process=False)
    closed = _closed_as_is(src)
    if closed is not None:
        return closed, {"method": "closed-as-is", "watertight": True, "faces": int(len(closed.faces))}
    level = cfg.level * pitch
    out = None
    for attempt, shift in enumerate((0.0, 0.37, 0.61)):  # a shifted grid avoids rare non-manifold cells
        vol, lo = _udf_grid(src, pitch, level, shift, cfg.max_cells)
        out = _isosurface(vol, lo, pitch, level)
        if _closed(out):
            break
    if cfg.max_faces and len(out.faces) > cfg.max_faces:
        dec = _decimate(out, cfg.max_faces)
        if dec is not None:  # else keep the full-resolution surface
            out = dec
    if out is None or not len(out.faces):
        raise RsartError("watertight remesh produced no surface")
    info: dict[str, Any] = {"method": "udf-offset", "watertight": bool(out.is_watertight),
                            "pitch": float(pitch), "level": float(level), "faces": int(len(out.faces)),
                            "attempts": attempt + 1}
    if cfg.chamfer_samples:
        cd, floor = _sampled_chamfer(src, out, cfg.chamfer_samples)
        info["chamfer_vs_original"] = round(cd, 6)
        info["chamfer_floor"] = round(floor, 6)
    return out, info


def describe_watertight(info: dict[str, Any]) -> str:
    """One readable line for a part's watertight record (``part.extra["watertight"]``)."""
    if info.get("method") == "closed-as-is":
        return f"closed as is, {info.get('faces')} faces"
    out = f"remeshed (offset {info.get('level', 0):.3g}, grid {info.get('pitch', 0):.3g}), {info.get('faces')} faces"
    if "chamfer_vs_original" in info:
        out += f", Chamfer to the original {info['chamfer_vs_original']:.3g} (floor {info.get('chamfer_floor', 0):.3g})"
    return out + ("" if info.get("watertight", True) else ", NOT watertight")


class PartProgress:
    """A tqdm progress bar over one object's parts on stderr (shown only on a terminal), for the
    ``progress`` callback of :func:`with_watertight_meshes`: ``progress(done, total, part_name)``;
    ``close()`` when the object is finished. ``enabled=False`` shows nothing."""

    def __init__(self, desc: str, enabled: bool = True):
        self.desc, self.enabled, self.bar = desc, enabled, None

    def __call__(self, done: int, total: int, name: str) -> None:
        if not self.enabled:
            return
        if self.bar is None:
            import sys

            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=self.desc, unit="part", file=sys.stderr, leave=False, disable=None)
        self.bar.set_postfix_str(name)
        self.bar.update(done - self.bar.n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def with_watertight_meshes(twin: Twin, cfg: WatertightConfig = WatertightConfig(),
                           log=None, progress=None) -> Twin:
    """The twin with each part's ``mesh`` replaced by its watertight copy; the original meshes become (or
    stay) the part's ``visuals``; the copy's record goes to ``part.extra["watertight"]``.

    ``log(msg)`` gets one readable line per part; ``progress(done, total, part_name)`` is called before
    each part (``done`` parts finished, ``part_name`` in the works) and once at the end (for a progress bar)."""
    b = np.array([[np.inf] * 3, [-np.inf] * 3])
    for p in twin.parts:
        if len(p.mesh.vertices):
            b[0] = np.minimum(b[0], p.mesh.bounds[0])
            b[1] = np.maximum(b[1], p.mesh.bounds[1])
    obj_diag = float(np.linalg.norm(b[1] - b[0]))
    parts = []
    for p in twin.parts:
        if progress:  # before each part: the bar shows which part is being remeshed
            progress(len(parts), len(twin.parts), p.name)
        part_diag = float(np.linalg.norm(p.mesh.extents)) or obj_diag
        try:
            wt, info = watertight_copy(p.mesh, cfg.pitch(obj_diag, part_diag), cfg)
        except RsartError as e:
            raise RsartError(f"{twin.name}: part {p.name!r}: {e}") from None
        if log:
            log(f"  part {p.name}: {describe_watertight(info)}")
        vis = p.visuals or [p.mesh]
        parts.append(TwinPart(p.index, p.name, wt, vis, {**p.extra, "watertight": info}))
    if progress:
        progress(len(parts), len(twin.parts), "done")
    return Twin(twin.name, parts, list(twin.joints))


# ----------------------------------------------------------------------------- generic URDF
def convert_urdf(src: str | os.PathLike, out: str | os.PathLike, *, object_id: str | None = None,
                 category: str | None = None, units: str | None = None, scale: float | None = None,
                 overwrite: bool = False, watertight: WatertightConfig = WatertightConfig(),
                 log=None, progress=None) -> ObjectMeta:
    """Convert any URDF file into an RS-Art object folder at ``out`` (written atomically).

    ``units``: what the URDF's numbers are ("m" for ROS-style URDFs, "scene" for unitless ones); with
    ``scale`` the geometry is multiplied by it and ``units`` becomes "m". A URDF that rsart wrote
    (``twin/object.urdf``) keeps its object id, category, units and source (provenance, with
    ``converted_from`` added); otherwise ``object_id`` defaults to the safe form of the file stem,
    ``category`` to "unknown", ``units`` to "m".
    """
    from ..states import QUARTER_TURN
    from ..twin_io import write_object
    from ..urdf import _safe_name, read_urdf, read_urdf_object_info

    src = Path(src)
    twin = read_urdf(src)
    info = read_urdf_object_info(src)
    units = units or (info.get("units") if info.get("units") in ("m", "scene") else "m")
    twin, notes = fold_helper_parts(twin, str(src))
    check_geometry(twin, str(src))
    extra: dict[str, Any] = {"converted_from": src.name}
    if scale is not None:
        twin = scale_twin(twin, scale)
        extra["scale_to_metres"] = float(scale)
        units = "m"
    twin = with_watertight_meshes(twin, watertight, log, progress)
    extra.update(conversion_notes(twin, notes, QUARTER_TURN, source=str(src)))
    source = ({**info["source"], "converted_from": {"kind": "urdf", "file": src.name}} if "source" in info
              else {"kind": "urdf", "id": src.name})
    return write_object(twin, out, object_id=object_id or info.get("object_id") or _safe_name(src.stem),
                        category=category or info.get("category") or "unknown", source=source, units=units,
                        extra_meta=extra, overwrite=overwrite)


def conversion_notes(twin: Twin, notes: list[str], unlimited_range: tuple[float, float],
                     source: str | None = None) -> dict[str, Any]:
    """meta.json ``extra`` keys shared by the URDF importers: notes, unlimited joints' state range.

    Texture images that the meshes' materials reference but that could not be read
    (``part.extra["missing_textures"]``, set by :func:`rsart.urdf.read_urdf`) are warned about once
    for the whole object (:class:`MissingTextureWarning`) and recorded as a note."""
    out: dict[str, Any] = {}
    missing = sorted({t for p in twin.parts for t in p.extra.get("missing_textures", [])})
    if missing:
        shown = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
        msg = (f"{len(missing)} texture image(s) or material file(s) referenced by the meshes are missing: "
               f"{shown}; those surfaces are converted and rendered untextured")
        warnings.warn(f"{source or twin.name}: {msg}", MissingTextureWarning, stacklevel=2)
        notes = [*notes, msg]
    if notes:
        out["conversion_notes"] = list(notes)
    free = [j.name for j in twin.joints if j.limits is None]
    if free:
        out["unlimited_joints"] = {
            "joints": free, "state_range": [float(unlimited_range[0]), float(unlimited_range[1])],
            "note": "continuous joints have no limits (limits: null); their states use this range "
                    "(a quarter turn, radians) for the multi and single states"}
    return out
