"""Reading geometry prims of a USD stage into trimeshes: meshes, gprims, UVs, textures, display colours.

What :mod:`rsart.usd_read` needs besides the joints: the Y-up to Z-up rotation, axis tokens,
quaternions and authored attributes, and :func:`body_meshes` (the geometry and visuals of one part,
in rsart's world at rest). Frames: rsart world = object base frame at rest, Z up, metres.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from .errors import Problems

# Rotation taking a Y-up stage into rsart's Z-up world (+90 deg about X): (x, y, z) -> (x, -z, y).
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
AXIS_VECTORS = {"X": np.array([1.0, 0.0, 0.0]), "Y": np.array([0.0, 1.0, 0.0]), "Z": np.array([0.0, 0.0, 1.0])}


def matrix_from_quat(w: float, x: float, y: float, z: float) -> np.ndarray:
    """(3, 3) rotation of a unit quaternion given scalar-first."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat([x, y, z, w]).as_matrix()


def custom_attr(prim, name: str):
    """The authored value of attribute ``name`` on ``prim``, or None."""
    a = prim.GetAttribute(name)
    return a.Get() if a and a.HasAuthoredValue() else None


# ----------------------------------------------------------------------------- geometry
@dataclass
class _Piece:
    """One geometry prim of a body, in rsart's world at rest: merged ``geom`` and optional textured ``visual``."""

    path: str
    role: str | None  # rsart:role ("geometry" | "visual") or None for foreign files
    renderable: bool
    geom: trimesh.Trimesh
    visual: trimesh.Trimesh | None


def _triangulate(counts: np.ndarray, indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate USD polygons: ((T, 3) corner indices into ``indices``, (T,) source face of each).

    Hand-written because USD polygons arrive as (counts, indices) arrays; a fan is exact for the
    convex polygons DCC tools export and keeps faceVarying primvars addressable per corner.
    """
    ntri = counts - 2
    face = np.repeat(np.arange(len(counts)), ntri)
    starts = np.cumsum(counts) - counts
    k = np.arange(len(face)) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    c0 = starts[face]
    return np.stack([c0, c0 + k + 1, c0 + k + 2], axis=1), face


def _primvar(prim, name: str):
    """(flattened values array, interpolation) of primvar ``name``, or None."""
    from pxr import UsdGeom

    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar(name)
    if not pv or not pv.HasValue():
        return None
    try:
        vals = pv.ComputeFlattened()
        return (np.array(vals, dtype=np.float64) if vals is not None else None), str(pv.GetInterpolation())
    except (TypeError, ValueError):  # a wrongly typed primvar is ignored like a missing one
        return None


def _texture(prim, root_dir: Path):
    """(PIL image, uv primvar name) of the UsdUVTexture feeding the bound material's diffuseColor, or None."""
    from pxr import UsdShade

    mat, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
    if not mat:
        return None
    surf = mat.ComputeSurfaceSource()[0]
    inp = surf.GetInput("diffuseColor") if surf else None
    srcs = inp.GetConnectedSources()[0] if inp else []
    if not srcs:
        return None
    tex = UsdShade.Shader(srcs[0].source.GetPrim())
    if tex.GetIdAttr().Get() != "UsdUVTexture" or not tex.GetInput("file"):
        return None
    asset = tex.GetInput("file").Get()
    varname = "st"
    st = tex.GetInput("st")
    st_src = st.GetConnectedSources()[0] if st else []
    if st_src:
        vn = UsdShade.Shader(st_src[0].source.GetPrim()).GetInput("varname")
        if vn and vn.Get():
            varname = str(vn.Get())
    resolved = getattr(asset, "resolvedPath", "") if asset is not None else ""
    where = f"{prim.GetPath()}: texture {getattr(asset, 'path', asset)!r}"
    if not resolved or "[" in resolved:
        warnings.warn(f"{where} not found (or packaged); the visual is kept untextured", stacklevel=3)
        return None
    p = Path(resolved).resolve()
    if root_dir not in p.parents:
        warnings.warn(f"{where} lies outside {root_dir}; not read", stacklevel=3)
        return None
    try:
        from PIL import Image

        with Image.open(p) as im:
            img = im.convert("RGBA") if im.mode in ("RGBA", "LA", "P") else im.convert("RGB")
    except Exception as e:  # a broken texture should not sink the geometry
        warnings.warn(f"{where} cannot be read ({e}); the visual is kept untextured", stacklevel=3)
        return None
    return img, varname


def _colors(prim, n_points: int, n_faces: int, face_of_tri: np.ndarray):
    """trimesh ColorVisuals kwargs from displayColor/displayOpacity (vertex, uniform or constant), or {}."""
    col = _primvar(prim, "displayColor")
    if col is None or col[0] is None or col[0].ndim != 2 or col[0].shape[1] != 3 or not np.all(np.isfinite(col[0])):
        return {}
    rgb, interp = col
    op = _primvar(prim, "displayOpacity")
    alpha = op[0] if op is not None and op[0] is not None and op[0].shape == (len(rgb),) else np.ones(len(rgb))
    rgba = np.clip(np.round(np.column_stack([rgb, alpha]) * 255.0), 0, 255).astype(np.uint8)
    if interp in ("vertex", "varying") and len(rgba) == n_points:
        return {"vertex_colors": rgba}
    if interp == "uniform" and len(rgba) == n_faces:
        return {"face_colors": rgba[face_of_tri]}
    if interp == "constant" and len(rgba) >= 1:
        return {"face_colors": np.repeat(rgba[:1], len(face_of_tri), axis=0)}
    return {}


def _gprim_mesh(prim, pb: Problems) -> trimesh.Trimesh | None:
    """Cube/Sphere/Cylinder as a trimesh in the prim's local frame."""
    from pxr import UsdGeom

    pp = str(prim.GetPath())
    if prim.IsA(UsdGeom.Cube):
        dims = {"size": UsdGeom.Cube(prim).GetSizeAttr().Get()}
    elif prim.IsA(UsdGeom.Sphere):
        dims = {"radius": UsdGeom.Sphere(prim).GetRadiusAttr().Get()}
    else:
        c = UsdGeom.Cylinder(prim)
        dims = {"radius": c.GetRadiusAttr().Get(), "height": c.GetHeightAttr().Get()}
    if not all(v is not None and math.isfinite(v) and v > 0 for v in dims.values()):
        pb.add(pp, f"{prim.GetTypeName()} needs positive finite dimensions, got {dims}")
        return None
    if "size" in dims:
        return trimesh.creation.box(extents=[dims["size"]] * 3)
    if "height" not in dims:
        return trimesh.creation.icosphere(subdivisions=3, radius=dims["radius"])
    m = trimesh.creation.cylinder(radius=dims["radius"], height=dims["height"], sections=48)
    axis = str(UsdGeom.Cylinder(prim).GetAxisAttr().Get())
    if axis in ("X", "Y"):
        m.apply_transform(trimesh.geometry.align_vectors([0, 0, 1], [1, 0, 0] if axis == "X" else [0, 1, 0]))
    return m


def _mesh_piece(prim, M: np.ndarray, root_dir: Path, pb: Problems) -> _Piece | None:
    """Read a UsdGeom.Mesh (or supported gprim) and place it with the (4, 4) transform ``M`` (rsart world)."""
    from pxr import Usd, UsdGeom

    pp = str(prim.GetPath())
    imageable = UsdGeom.Imageable(prim)
    renderable = imageable.ComputePurpose() in ("default", "render") and imageable.ComputeVisibility() != "invisible"
    role = custom_attr(prim, "rsart:role")
    role = role if role in ("geometry", "visual") else None
    if not np.all(np.isfinite(M)):
        pb.add(pp, "non-finite transform (NaN or inf)")
        return None
    flip = np.linalg.det(M[:3, :3]) < 0
    if not prim.IsA(UsdGeom.Mesh):
        m = _gprim_mesh(prim, pb)
        if m is None:
            return None
        m = trimesh.Trimesh(m.vertices, m.faces, process=False)
        m.apply_transform(M)
        return _Piece(pp, role, renderable, m, None)
    mesh = UsdGeom.Mesh(prim)
    t = Usd.TimeCode.EarliestTime()  # the default value, else the first time sample
    pts, counts, idx = (mesh.GetPointsAttr().Get(t), mesh.GetFaceVertexCountsAttr().Get(t),
                        mesh.GetFaceVertexIndicesAttr().Get(t))
    try:
        v = np.array(pts, dtype=np.float64).reshape(-1, 3) if pts is not None and len(pts) else np.zeros((0, 3))
        counts = np.array(counts, dtype=np.int64).reshape(-1) if counts is not None else np.zeros(0, np.int64)
        idx = np.array(idx, dtype=np.int64).reshape(-1) if idx is not None else np.zeros(0, np.int64)
    except (TypeError, ValueError):
        pb.add(pp, "points/faceVertexCounts/faceVertexIndices are not point3f[]/int[]/int[] arrays")
        return None
    if len(v) == 0:
        pb.add(pp, "mesh has no points")
        return None
    if not np.all(np.isfinite(v)):
        pb.add(pp, "mesh points contain NaN or inf")
        return None
    if len(counts) == 0:
        pb.add(pp, "mesh has no faces")
        return None
    if np.any(counts < 3) or int(counts.sum()) != len(idx):
        pb.add(pp, "faceVertexCounts must be >= 3 and sum to len(faceVertexIndices)")
        return None
    if np.any(idx < 0) or np.any(idx >= len(v)):
        pb.add(pp, f"faceVertexIndices outside [0, {len(v) - 1}]")
        return None
    corners, face = _triangulate(counts, idx)
    if str(mesh.GetOrientationAttr().Get()) == "leftHanded":
        flip = not flip
    if flip:
        corners = corners[:, [0, 2, 1]]
    vw = v @ M[:3, :3].T + M[:3, 3]
    geom = trimesh.Trimesh(vw, idx[corners], process=False)
    colors = _colors(prim, len(v), len(counts), face)
    if colors:
        geom.visual = trimesh.visual.ColorVisuals(geom, **colors)
    visual = None
    try:
        tex = _texture(prim, root_dir)
    except Exception as e:  # a malformed material network leaves the mesh untextured, never sinks it
        warnings.warn(f"{pp}: material not understood ({type(e).__name__}: {e}); kept untextured", stacklevel=2)
        tex = None
    if tex is not None:
        uv = _primvar(prim, tex[1])
        ok = (uv is not None and uv[0] is not None and uv[0].ndim == 2 and uv[0].shape[1] == 2
              and bool(np.all(np.isfinite(uv[0]))))
        if ok and uv[1] in ("vertex", "varying") and len(uv[0]) == len(v):
            visual = trimesh.Trimesh(vw, idx[corners], process=False,
                                     visual=trimesh.visual.TextureVisuals(uv=uv[0], image=tex[0]))
        elif ok and uv[1] == "faceVarying" and len(uv[0]) == len(idx):
            flat = corners.reshape(-1)
            visual = trimesh.Trimesh(vw[idx[flat]], np.arange(len(flat)).reshape(-1, 3), process=False,
                                     visual=trimesh.visual.TextureVisuals(uv=uv[0][flat], image=tex[0]))
        else:
            warnings.warn(f"{pp}: texture coordinates {tex[1]!r} missing or mismatched; kept untextured", stacklevel=2)
    return _Piece(pp, role, renderable, geom, visual)


def _concat(meshes: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    """One mesh of several (geometry only; a single mesh is returned as is, colours kept)."""
    if len(meshes) == 1:
        return meshes[0]
    offs = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    return trimesh.Trimesh(np.vstack([m.vertices for m in meshes]),
                           np.vstack([m.faces + o for m, o in zip(meshes, offs)]), process=False)


def body_meshes(stage, members: list[str], bodies: set[str], C: np.ndarray, D: dict, world, root_dir: Path,
                pb: Problems) -> tuple[trimesh.Trimesh | None, list[trimesh.Trimesh]]:
    """(geometry, visuals) of a part made of ``members`` bodies, rsart world at rest. Problems name prims."""
    from pxr import Usd, UsdGeom

    pieces: list[_Piece] = []
    seen = 0
    for b in members:
        top = stage.GetPrimAtPath(b)
        it = iter(Usd.PrimRange(top, Usd.TraverseInstanceProxies()))
        for p in it:
            ps = str(p.GetPath())
            if p != top and ps in bodies:
                it.PruneChildren()
                continue
            if p.IsA(UsdGeom.Mesh) or p.IsA(UsdGeom.Cube) or p.IsA(UsdGeom.Sphere) or p.IsA(UsdGeom.Cylinder):
                seen += 1
                piece = _mesh_piece(p, C @ D[b] @ world(ps), root_dir, pb)
                if piece is not None:
                    pieces.append(piece)
    if len(pieces) < seen:  # some geometry prims were invalid (problems recorded)
        return None, []
    empty = trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), process=False)
    if not pieces:  # a body without geometry (a helper link): an empty part
        return empty, []
    if any(p.role for p in pieces):
        geo = [p.geom for p in pieces if p.role == "geometry"] or [empty]
        vis = [p.visual or p.geom for p in pieces if p.role == "visual"]
        return _concat(geo), vis
    chosen = [p for p in pieces if p.renderable] or pieces
    vis = [p.visual or p.geom for p in chosen] if any(p.visual is not None for p in chosen) else []
    return _concat([p.geom for p in chosen]), vis
