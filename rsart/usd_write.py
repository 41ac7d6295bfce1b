"""rsart's USD writer: a Twin -> a ``.usda`` UsdPhysics articulation (see :func:`rsart.usd.write_usd`).

Layout (``<root>`` = the twin's name made a valid prim name)::

    /<root>                       Xform, PhysicsArticulationRootAPI (defaultPrim)
    /<root>/<part>                Xform (translate = part bbox centre, double), PhysicsRigidBodyAPI
    /<root>/<part>/geometry       Mesh, points relative to the part frame, PhysicsCollisionAPI,
                                  purpose "guide" when the part has visuals
    /<root>/<part>/visuals/visual_<k>   Mesh with primvars:st + bound material (textured visuals)
    /<root>/Looks/<part>_visual_<k>     UsdPreviewSurface + UsdUVTexture (relative asset path)
    /<root>/joints/<joint>        PhysicsRevoluteJoint | PhysicsPrismaticJoint, axis "X"
    /<root>/joints/rsart_base_fixed     PhysicsFixedJoint anchoring the base to the world
    /physicsScene                 PhysicsScene (gravity -Z)

A joint frame has its X axis along the joint axis and its origin on the axis; ``localPos0/1`` are
that point in the parent/child part frames, ``localRot0/1`` the frame's rotation (identical, part
frames are unrotated). Revolute limits in degrees; an unlimited revolute joint has no limits.
"""
from __future__ import annotations

import io
import os
import re
from pathlib import Path

import numpy as np
import trimesh

from .checks import unique_name
from .errors import RsartError
from .io import atomic_write_bytes, atomic_write_text, dumps_json
from .kinematics import Twin, TwinPart

RSART_USD_FORMAT = "rsart-usd/1"
_IDENT = re.compile(r"[^A-Za-z0-9_]")


def prim_name(name: str, taken: set[str]) -> str:
    """A valid, unique USD prim name for ``name`` (invalid characters -> '_', leading digit prefixed)."""
    base = _IDENT.sub("_", name) or "_"
    if base[0].isdigit():
        base = "_" + base
    return unique_name(base, taken)


def quat_from_matrix(R: np.ndarray) -> tuple[float, float, float, float]:
    """(w, x, y, z) unit quaternion of a (3, 3) rotation matrix (scipy, scalar-last -> scalar-first)."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_quat()
    return float(w), float(x), float(y), float(z)


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


def _texture_image(visual) -> "object | None":
    """The PIL image of a trimesh TextureVisuals (SimpleMaterial.image or PBR baseColorTexture), or None."""
    mat = getattr(visual, "material", None)
    if mat is None:
        return None
    img = getattr(mat, "image", None)
    if img is None:
        img = getattr(mat, "baseColorTexture", None)
    return img


def _is_textured(m: trimesh.Trimesh) -> bool:
    v = m.visual
    return (getattr(v, "kind", None) == "texture" and getattr(v, "uv", None) is not None
            and len(v.uv) == len(m.vertices) and _texture_image(v) is not None)


def _png_bytes(img) -> bytes:
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()


def _mesh_prim(stage, path, vertices: np.ndarray, faces: np.ndarray):
    from pxr import UsdGeom, Vt

    mesh = UsdGeom.Mesh.Define(stage, path)
    pts = np.ascontiguousarray(vertices, dtype=np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts))
    f = np.ascontiguousarray(faces, dtype=np.int32)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(f), 3, dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(f.reshape(-1)))
    mesh.CreateSubdivisionSchemeAttr("none")
    if len(pts):
        mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([pts.min(0), pts.max(0)])))
    return mesh


def _set_role(prim, role: str) -> None:
    from pxr import Sdf

    prim.CreateAttribute("rsart:role", Sdf.ValueTypeNames.String, custom=True).Set(role)


def _set_extra(prim, extra: dict) -> None:
    """Keep a part's/joint's ``extra`` dict as JSON in ``rsart:extra`` (skipped when empty or not JSON)."""
    from pxr import Sdf

    if not extra:
        return
    try:
        text = dumps_json(extra)
    except (TypeError, ValueError):
        return
    prim.CreateAttribute("rsart:extra", Sdf.ValueTypeNames.String, custom=True).Set(text)


def _colors(m: trimesh.Trimesh) -> tuple[str, np.ndarray] | None:
    """("vertex"|"uniform", (N, 4) float RGBA in [0, 1]) for colour visuals that carry colours, else None."""
    v = m.visual
    kind = getattr(v, "kind", None)
    if kind == "vertex":
        return "vertex", np.asarray(v.vertex_colors, dtype=np.float64) / 255.0
    if kind == "face":
        return "uniform", np.asarray(v.face_colors, dtype=np.float64) / 255.0
    if kind == "texture" and getattr(v, "material", None) is not None:  # untextured material: its main colour
        c = np.asarray(v.material.main_color, dtype=np.float64) / 255.0
        return "constant", c[None, :]
    return None


def _write_colors(mesh, colors: tuple[str, np.ndarray]) -> None:
    from pxr import Sdf, UsdGeom, Vt

    interp, rgba = colors
    pv = UsdGeom.PrimvarsAPI(mesh.GetPrim())
    pv.CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray, interp).Set(
        Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(rgba[:, :3], dtype=np.float32)))
    pv.CreatePrimvar("displayOpacity", Sdf.ValueTypeNames.FloatArray, interp).Set(
        Vt.FloatArray.FromNumpy(np.ascontiguousarray(rgba[:, 3], dtype=np.float32)))


def _material(stage, path: str, texture: str):
    """A UsdPreviewSurface material whose diffuse colour reads ``texture`` through primvar ``st``."""
    from pxr import Sdf, UsdShade

    mat = UsdShade.Material.Define(stage, path)
    surf = UsdShade.Shader.Define(stage, f"{path}/surface")
    surf.CreateIdAttr("UsdPreviewSurface")
    surf.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.8)
    reader = UsdShade.Shader.Define(stage, f"{path}/st_reader")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    tex = UsdShade.Shader.Define(stage, f"{path}/texture")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(texture))
    tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB")
    tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("repeat")
    tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("repeat")
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
        reader.ConnectableAPI(), "result")
    tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(tex.ConnectableAPI(), "rgb")
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    return mat


def _texture_ref(usd_dir: Path, part: TwinPart, k: int, pname: str, texture_files: dict | None,
                 pending: dict[Path, bytes]) -> str:
    """The asset path (relative to the .usda) of visual ``k``'s texture; queues its PNG if rsart writes it
    (once per distinct image)."""
    given = (texture_files or {}).get(part.index)
    if given is not None and k < len(given) and given[k]:
        ref = str(given[k])
        if os.path.isabs(ref):
            ref = os.path.relpath(ref, usd_dir)
        return ref.replace(os.sep, "/")
    data = _png_bytes(_texture_image(part.visuals[k].visual))
    for path, queued in pending.items():  # visuals sharing one image (an atlas) share one file
        if queued == data:
            return path.relative_to(usd_dir).as_posix()
    rel = f"textures/{pname}_{k}.png"
    pending[usd_dir / rel] = data
    return rel


def _write_part(stage, root: str, part: TwinPart, pname: str, usd_dir: Path, texture_files, pending) -> np.ndarray:
    """Author the part's rigid body; returns its frame origin (3,) (bbox centre, world, metres)."""
    from pxr import Gf, Sdf, UsdGeom, UsdPhysics, UsdShade, Vt

    verts = np.asarray(part.mesh.vertices, dtype=np.float64)
    empty = len(verts) == 0 or len(part.mesh.faces) == 0  # e.g. a URDF helper link: a body without geometry
    allv = verts if not empty else np.concatenate([np.zeros((0, 3))] + [np.asarray(v.vertices) for v in part.visuals])
    centre = 0.5 * (allv.min(0) + allv.max(0)) if len(allv) else np.zeros(3)
    xf = UsdGeom.Xform.Define(stage, f"{root}/{pname}")
    xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*centre.tolist()))
    prim = xf.GetPrim()
    prim.CreateAttribute("rsart:name", Sdf.ValueTypeNames.String, custom=True).Set(part.name)
    _set_extra(prim, part.extra)
    UsdPhysics.RigidBodyAPI.Apply(prim)

    if not empty:
        geom = _mesh_prim(stage, f"{root}/{pname}/geometry", verts - centre, part.mesh.faces)
        _set_role(geom.GetPrim(), "geometry")
        UsdPhysics.CollisionAPI.Apply(geom.GetPrim())
        UsdPhysics.MeshCollisionAPI.Apply(geom.GetPrim()).CreateApproximationAttr("convexDecomposition")
        if part.visuals:
            geom.CreatePurposeAttr("guide")
        elif (c := _colors(part.mesh)) is not None:
            _write_colors(geom, c)

    if part.visuals:
        UsdGeom.Scope.Define(stage, f"{root}/{pname}/visuals")
    for k, vm in enumerate(part.visuals):
        if len(vm.vertices) == 0 or len(vm.faces) == 0:
            continue
        vpath = f"{root}/{pname}/visuals/visual_{k}"
        vmesh = _mesh_prim(stage, vpath, np.asarray(vm.vertices, dtype=np.float64) - centre, vm.faces)
        _set_role(vmesh.GetPrim(), "visual")
        if _is_textured(vm):
            st = UsdGeom.PrimvarsAPI(vmesh.GetPrim()).CreatePrimvar(
                "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
            st.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(vm.visual.uv, dtype=np.float32)))
            ref = _texture_ref(usd_dir, part, k, pname, texture_files, pending)
            mat = _material(stage, f"{root}/Looks/{pname}_visual_{k}", ref)
            UsdShade.MaterialBindingAPI.Apply(vmesh.GetPrim()).Bind(mat)
        elif (c := _colors(vm)) is not None:
            _write_colors(vmesh, c)
    return centre


def _write_joint(stage, root: str, j, jname: str, body_paths: list[str], centres: list[np.ndarray],
                 units_scale: float) -> None:
    from pxr import Gf, Sdf, UsdPhysics

    path = f"{root}/joints/{jname}"
    jt = UsdPhysics.RevoluteJoint.Define(stage, path) if j.type == "revolute" else \
        UsdPhysics.PrismaticJoint.Define(stage, path)
    axis = np.asarray(j.axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    origin = np.asarray(j.origin, dtype=np.float64)
    w, x, y, z = quat_from_matrix(rotation_x_to(axis))
    if w < 0:  # canonical sign (q and -q are the same rotation)
        w, x, y, z = -w, -x, -y, -z
    q = Gf.Quatf(w, Gf.Vec3f(x, y, z))
    jt.CreateBody0Rel().SetTargets([Sdf.Path(body_paths[j.parent])])
    jt.CreateBody1Rel().SetTargets([Sdf.Path(body_paths[j.child])])
    jt.CreateLocalPos0Attr(Gf.Vec3f(*(origin - centres[j.parent]).tolist()))
    jt.CreateLocalRot0Attr(q)
    jt.CreateLocalPos1Attr(Gf.Vec3f(*(origin - centres[j.child]).tolist()))
    jt.CreateLocalRot1Attr(q)
    jt.CreateAxisAttr("X")
    if j.limits is not None:
        lo, hi = j.limits
        if j.type == "revolute":
            lo, hi = np.degrees(lo), np.degrees(hi)
        else:
            lo, hi = lo / units_scale, hi / units_scale
        jt.CreateLowerLimitAttr(float(lo))
        jt.CreateUpperLimitAttr(float(hi))
    p = jt.GetPrim()
    p.CreateAttribute("rsart:name", Sdf.ValueTypeNames.String, custom=True).Set(j.name)
    _set_extra(p, j.extra)
    p.CreateAttribute("rsart:axis", Sdf.ValueTypeNames.Double3, custom=True).Set(Gf.Vec3d(*axis.tolist()))
    p.CreateAttribute("rsart:origin", Sdf.ValueTypeNames.Double3, custom=True).Set(Gf.Vec3d(*origin.tolist()))
    if j.limits is not None:
        p.CreateAttribute("rsart:limits", Sdf.ValueTypeNames.Double2, custom=True).Set(
            Gf.Vec2d(float(j.limits[0]), float(j.limits[1])))


def build_stage(twin: Twin, usd_dir: Path, units: str = "m", texture_files: dict | None = None):
    """(stage, pending texture PNGs {path: bytes}) of ``twin`` in rsart's layout (in memory)."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics

    if units not in ("m", "scene"):
        raise RsartError(f"units must be 'm' or 'scene', got {units!r}")
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    layer = stage.GetRootLayer()
    layer.customLayerData = {"rsart:format": RSART_USD_FORMAT, "rsart:units": units, "rsart:twinName": twin.name}
    root = "/" + prim_name(twin.name, set())
    UsdPhysics.ArticulationRootAPI.Apply(UsdGeom.Xform.Define(stage, root).GetPrim())
    stage.SetDefaultPrim(stage.GetPrimAtPath(root))
    scene = UsdPhysics.Scene.Define(stage, "/physicsScene")
    scene.CreateGravityDirectionAttr(Gf.Vec3f(0, 0, -1))
    scene.CreateGravityMagnitudeAttr(9.81)

    for scope in ("joints", "Looks"):
        UsdGeom.Scope.Define(stage, f"{root}/{scope}")
    taken = {"joints", "Looks"}
    pnames = [prim_name(p.name, taken) for p in twin.parts]
    pending: dict[Path, bytes] = {}
    centres = [_write_part(stage, root, p, pn, usd_dir, texture_files, pending) for p, pn in zip(twin.parts, pnames)]
    body_paths = [f"{root}/{pn}" for pn in pnames]
    jtaken = {"rsart_base_fixed"}
    for j in twin.joints:
        _write_joint(stage, root, j, prim_name(j.name, jtaken), body_paths, centres, 1.0)
    fixed = UsdPhysics.FixedJoint.Define(stage, f"{root}/joints/rsart_base_fixed")
    fixed.CreateBody1Rel().SetTargets([Sdf.Path(body_paths[0])])
    fixed.CreateLocalPos0Attr(Gf.Vec3f(*centres[0].tolist()))
    return stage, pending


def write_usd(twin: Twin, path: str | Path, *, units: str = "m", texture_files: dict | None = None,
              object_info: dict | None = None) -> None:
    """See :func:`rsart.usd.write_usd`. Texture PNGs first, then the ``.usda`` (each atomically)."""
    import json

    path = Path(path)
    if path.suffix != ".usda":
        raise RsartError(f"{path}: rsart writes USD as text; use a .usda file name")
    stage, pending = build_stage(twin, path.parent.absolute(), units, texture_files)
    if object_info:
        layer = stage.GetRootLayer()
        layer.customLayerData = {**layer.customLayerData, "rsart:object": json.dumps(object_info, sort_keys=True)}
    text = stage.GetRootLayer().ExportToString()
    for p, data in pending.items():
        atomic_write_bytes(p, data)
    atomic_write_text(path, text)
