"""Read and write URDF twins.

Reading (any URDF, treated as untrusted): the XML is first checked with defusedxml (no DTD,
no entities: billion-laughs and external-entity files are refused), then parsed with yourdfpy
(which accepts ``<limit>`` without ``effort``/``velocity``, as every PartNet-Mobility file has).
Links joined by ``fixed`` joints merge into one part; ``continuous`` joints become revolute
joints without limits; mesh files are resolved only inside the URDF's folder.

World frame: the URDF root link's frame. Joint axes/origins are converted to that frame at the
rest configuration (all joint values 0), which is how :class:`rsart.kinematics.Twin` stores them.

Writing: one link per part, link frames world-aligned and placed at the joint origin, meshes
referenced from ``twin/visual/`` (MuJoCo looks meshes up by file name in one ``meshdir``), and a
``<mujoco>`` block so ``mujoco.MjModel.from_xml_path`` keeps visual meshes.
"""
from __future__ import annotations

import contextlib
import io
import json
import logging
import math
import os
import re
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np
import trimesh

from .errors import Problems, RsartError
from .format import Joint
from .io import atomic_write_text, resolve_inside
from .kinematics import Twin, TwinPart

MAX_URDF_BYTES = 20 * 1024 * 1024
MOVING = {"revolute": "revolute", "continuous": "revolute", "prismatic": "prismatic"}

def _safe_name(s: str) -> str:
    out = re.sub(r"[^A-Za-z0-9_.\-]", "_", s).strip("._-") or "part"
    return out[:100]

def check_xml(data: bytes, source: str) -> None:
    """Refuse XML with a DTD or entities (billion laughs, external entities) and malformed XML; raises RsartError."""
    import defusedxml.ElementTree as DET
    from defusedxml import DefusedXmlException

    try:
        DET.fromstring(data, forbid_dtd=True)
    except DefusedXmlException as e:
        raise RsartError(f"{source}: refused: the XML declares a DTD or entities ({type(e).__name__}); "
                         "URDF files need neither") from None
    except Exception as e:  # ParseError and friends
        raise RsartError(f"{source}: not well-formed XML ({e})") from None
    # yourdfpy parses with lxml, which refuses what ElementTree accepts beyond its limits (nesting deeper
    # than 256 levels, huge text nodes); yourdfpy then logs the error and re-parses in "recover" mode,
    # silently dropping elements. Refuse such files here, with lxml's reason, instead.
    from lxml import etree

    try:
        etree.fromstring(data, etree.XMLParser(resolve_entities=False, no_network=True, remove_blank_text=True))
    except etree.XMLSyntaxError as e:
        raise RsartError(f"{source}: XML the URDF parser refuses ({e})") from None


@contextlib.contextmanager
def _quiet_library_logs():
    """Silence yourdfpy's (and lxml's) log records while parsing: rsart reports problems as one error."""
    loggers = [logging.getLogger(n) for n in ("yourdfpy", "lxml", "trimesh")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for lg, lv in zip(loggers, levels):
            lg.setLevel(lv)

class _InsideResolver(trimesh.resolvers.FilePathResolver):
    """Resolve a mesh's side files (MTL, texture images) relative to the mesh's folder, but only inside
    ``root`` (PartNet-Mobility's MTLs say ``map_Kd ../images/texture_0.jpg``: outside the OBJ's folder, inside
    the object folder; trimesh's own resolver refuses that). Names that cannot be found are kept in ``missing``."""

    def __init__(self, mesh_path: Path, root: Path):
        super().__init__(str(mesh_path), allow_anywhere=True)
        self.root = Path(root).resolve()
        self.missing: list[str] = []

    def get(self, name: str):
        p = (Path(self.parent) / name.strip()).resolve()
        if p != self.root and self.root not in p.parents:
            self.missing.append(name.strip())
            raise FileNotFoundError(name)
        if not p.is_file():
            self.missing.append(name.strip())
            raise FileNotFoundError(name)
        return p.read_bytes()


def load_mesh_file(path: Path, scale: np.ndarray | None = None, *, root: Path | None = None,
                   missing: list[str] | None = None) -> list[trimesh.Trimesh]:
    """Load a mesh file (OBJ/PLY/STL/GLB/DAE) as a list of trimeshes, textures kept where present.

    Side files (MTL, texture images) are looked up relative to the mesh file and only inside ``root``
    (default: the mesh's folder). The names of texture images its materials reference but that cannot be
    read (and of material libraries, ``.mtl``) are appended to ``missing`` (when given), so callers can say
    so instead of rendering untextured.
    """
    path = Path(path)
    resolver = _InsideResolver(path, root if root is not None else path.parent)
    try:
        loaded = trimesh.load(str(path), process=False, resolver=resolver)
    except Exception as e:
        raise RsartError(f"{path}: cannot read mesh ({type(e).__name__}: {e})") from None
    if isinstance(loaded, trimesh.Scene):
        meshes = [g for g in loaded.dump(concatenate=False) if isinstance(g, trimesh.Trimesh)] \
            if hasattr(loaded, "dump") else list(loaded.geometry.values())
    elif isinstance(loaded, trimesh.Trimesh):
        meshes = [loaded]
    else:
        raise RsartError(f"{path}: contains no triangle mesh")
    if not any(len(m.faces) for m in meshes):  # e.g. a text file named .obj: trimesh reads it as empty
        raise RsartError(f"{path}: contains no triangles (not a mesh, or an empty one)")
    if missing is not None:  # material libraries and texture images the file names but we could not read
        missing.extend(dict.fromkeys(resolver.missing))
    if scale is not None:
        S = np.diag([*np.asarray(scale, dtype=float), 1.0])
        for m in meshes:
            m.apply_transform(S)
    return meshes

def _geometry_meshes(geom, base_dir: Path, source: str, where: str,
                     missing: list[str] | None = None) -> list[trimesh.Trimesh]:
    if geom is None:
        return []
    if geom.box is not None:
        return [trimesh.creation.box(extents=np.asarray(geom.box.size, dtype=float))]
    if geom.cylinder is not None:
        return [trimesh.creation.cylinder(radius=geom.cylinder.radius, height=geom.cylinder.length)]
    if geom.sphere is not None:
        return [trimesh.creation.icosphere(subdivisions=3, radius=geom.sphere.radius)]
    if geom.mesh is not None:
        fn = geom.mesh.filename or ""
        if fn.startswith("package://"):
            fn = fn.split("/", 3)[-1] if fn.count("/") >= 3 else fn[len("package://"):]
        if fn.startswith("file://"):
            fn = fn[len("file://"):]
        if os.path.isabs(fn):
            raise RsartError(f"{source}: {where}: absolute mesh path {fn!r} refused (meshes must lie inside {base_dir})")
        try:
            p = resolve_inside(base_dir, fn)
        except RsartError:
            raise RsartError(f"{source}: {where}: mesh path {fn!r} leaves the URDF folder") from None
        if not p.is_file():
            raise RsartError(f"{source}: {where}: mesh file {fn!r} not found")
        try:  # an unreadable or empty visual mesh is an error naming the link, never a silently empty part
            return load_mesh_file(p, geom.mesh.scale if geom.mesh.scale is not None else None,
                                  root=base_dir.resolve(), missing=missing)
        except RsartError as e:
            raise RsartError(f"{source}: {where}: {e}") from None
    return []

def read_urdf(path: str | os.PathLike, *, use: str = "visual", load_meshes: bool = True) -> Twin:
    """Read a URDF file into a :class:`Twin` (see module docstring for the rules).

    ``use``: "visual" (default; falls back to collision geometry for links without visuals) or
    "collision". Raises :class:`RsartError` / ValidationError naming the file and element.
    """
    import yourdfpy

    path = Path(path)
    source = str(path)
    try:
        size = path.stat().st_size
    except OSError as e:
        raise RsartError(f"{source}: cannot read ({e.strerror})") from None
    if size > MAX_URDF_BYTES:
        raise RsartError(f"{source}: {size} bytes exceeds the URDF size limit of {MAX_URDF_BYTES}")
    data = path.read_bytes()
    check_xml(data, source)
    try:
        with _quiet_library_logs():
            urdf = yourdfpy.URDF.load(io.BytesIO(data), load_meshes=False, build_scene_graph=False,
                                      build_collision_scene_graph=False, load_collision_meshes=False)
    except Exception as e:
        raise RsartError(f"{source}: not a valid URDF ({type(e).__name__}: {e})") from None
    robot = urdf.robot
    pb = Problems()
    links = {}
    for l in robot.links:
        if l.name in links:
            pb.add(f"link[{l.name}]", "duplicate link name")
        links[l.name] = l
    if not links:
        pb.add("robot", "no links")
    jnames, child_joint, children = set(), {}, {}
    for j in robot.joints:
        w = f"joint[{j.name}]"
        if j.name in jnames:
            pb.add(w, "duplicate joint name")
        jnames.add(j.name)
        if j.type not in MOVING and j.type != "fixed":
            pb.add(w, f"unsupported joint type {j.type!r} (rsart supports revolute, continuous, prismatic, fixed)")
        for end in (j.parent, j.child):
            if end not in links:
                pb.add(w, f"refers to unknown link {end!r}")
        if j.child in child_joint:
            pb.add(w, f"link {j.child!r} is the child of two joints")
        child_joint[j.child] = j
        children.setdefault(j.parent, []).append(j)
        if j.origin is None:
            j.origin = np.eye(4)
        if not np.all(np.isfinite(np.asarray(j.origin, dtype=float))):
            pb.add(f"{w}.origin", "non-finite number")
        if j.type in MOVING:
            ax = np.asarray(j.axis if j.axis is not None else [1, 0, 0], dtype=float)
            if not np.all(np.isfinite(ax)):
                pb.add(f"{w}.axis", "non-finite number")
            elif np.linalg.norm(ax) < 1e-12:
                pb.add(f"{w}.axis", "zero-length vector")
            lim = j.limit
            if j.type in ("revolute", "prismatic"):
                if lim is None or lim.lower is None or lim.upper is None:
                    if j.type == "prismatic":
                        pb.add(f"{w}.limit", "a prismatic joint needs <limit lower=.. upper=..>")
                elif not (math.isfinite(lim.lower) and math.isfinite(lim.upper)):
                    pb.add(f"{w}.limit", "non-finite limit")
                elif lim.lower > lim.upper:
                    pb.add(f"{w}.limit", f"lower {lim.lower} > upper {lim.upper}")
    roots = [n for n in links if n not in child_joint]
    if links and len(roots) != 1:
        pb.add("robot", f"expected exactly one root link, found {len(roots)}: {roots[:5]}"
               + (" (a joint cycle)" if not roots else ""))
    pb.raise_if_any(source)
    root = roots[0]

    # rest transforms of links and grouping into parts (fixed joints merge)
    T_link = {root: np.eye(4)}
    part_of = {root: 0}
    part_links: list[list[str]] = [[root]]
    part_joint: list = [None]
    order, stack, seen = [], [root], {root}
    while stack:
        ln = stack.pop()
        order.append(ln)
        for j in children.get(ln, []):
            if j.child in seen:
                raise RsartError(f"{source}: joint[{j.name}]: joint cycle through link {j.child!r}")
            seen.add(j.child)
            T_link[j.child] = T_link[ln] @ np.asarray(j.origin, dtype=float)
            if j.type == "fixed":
                part_of[j.child] = part_of[ln]
                part_links[part_of[ln]].append(j.child)
            else:
                part_of[j.child] = len(part_links)
                part_links.append([j.child])
                part_joint.append(j)
            stack.append(j.child)
    unreached = set(links) - seen
    if unreached:
        raise RsartError(f"{source}: links not connected to the root {root!r}: {sorted(unreached)[:5]}")

    parts, names = [], set()
    for pi, lnames in enumerate(part_links):
        name = "base" if pi == 0 else _safe_name(lnames[0])
        while name in names:
            name = f"{name}_{pi}"
        names.add(name)
        visuals: list[trimesh.Trimesh] = []
        missing: list[str] = []
        if load_meshes:
            for ln in lnames:
                link = links[ln]
                elems = link.visuals if use == "visual" and link.visuals else link.collisions
                for k, el in enumerate(elems):
                    where = f"link[{ln}].{'visual' if elems is link.visuals else 'collision'}[{k}]"
                    T = T_link[ln] @ (np.asarray(el.origin, dtype=float) if el.origin is not None else np.eye(4))
                    for m in _geometry_meshes(el.geometry, path.parent, source, where, missing):
                        m.apply_transform(T)
                        visuals.append(m)
        geom = (trimesh.util.concatenate([trimesh.Trimesh(m.vertices, m.faces, process=False) for m in visuals])
                if visuals else trimesh.Trimesh())
        extra = {"links": list(lnames)}
        if missing:
            extra["missing_textures"] = sorted(set(missing))
        parts.append(TwinPart(pi, name, geom, visuals, extra))

    joints = []
    for pi in range(1, len(part_links)):
        j = part_joint[pi]
        Tc = T_link[j.child]
        ax = np.asarray(j.axis if j.axis is not None else [1, 0, 0], dtype=float)
        ax_w = Tc[:3, :3] @ (ax / np.linalg.norm(ax))
        lim = None
        if j.type != "continuous" and j.limit is not None and j.limit.lower is not None and j.limit.upper is not None:
            lim = (float(j.limit.lower), float(j.limit.upper))
        extra = {"urdf_type": j.type} if j.type == "continuous" else {}
        joints.append(Joint(_safe_name(j.name), MOVING[j.type], part_of[j.parent], pi,
                            ax_w / np.linalg.norm(ax_w), Tc[:3, 3].copy(), lim, extra))
    return Twin(_safe_name(robot.name or path.stem), parts, joints)

# ----------------------------------------------------------------------------- writing
def _f(x: float) -> str:
    return repr(float(x))

def _v(a) -> str:
    return " ".join(_f(x) for x in a)

def urdf_text(twin: Twin, visual_files: dict[int, str], mesh_dir: str = "visual",
              masses: dict[int, float] | None = None, object_info: dict | None = None) -> str:
    """URDF XML of ``twin``; ``visual_files[part]`` is each part's mesh file name inside ``mesh_dir``.

    ``object_info`` (object_id, category, units, source) is kept in an ``<rsart>`` element (ignored by
    other URDF readers) so that converting the URDF back keeps them (:func:`read_urdf_object_info`)."""
    frame = {0: np.zeros(3)}
    for j in twin.joints:
        frame[j.child] = np.asarray(j.origin, dtype=float)
    lines = ['<?xml version="1.0"?>', f"<robot name={quoteattr(twin.name)}>",
             "  <mujoco>", f'    <compiler discardvisual="false" fusestatic="false" '
             'balanceinertia="true"/>', "  </mujoco>"]
    if object_info:
        lines.append(f"  <rsart info={quoteattr(json.dumps(object_info, sort_keys=True))}/>")
    for p in twin.parts:
        o = -frame[p.index]
        m = p.mesh
        mass = (masses or {}).get(p.index, 1.0)
        com = (m.bounds.mean(axis=0) if len(m.vertices) else np.zeros(3)) + o
        ext = np.maximum(m.extents if len(m.vertices) else np.ones(3) * 0.01, 1e-3)
        I = mass / 12.0 * np.array([ext[1] ** 2 + ext[2] ** 2, ext[0] ** 2 + ext[2] ** 2, ext[0] ** 2 + ext[1] ** 2])
        lines += [f"  <link name={quoteattr(p.name)}>",
                  f'    <inertial><origin xyz="{_v(com)}"/><mass value="{_f(mass)}"/>'
                  f'<inertia ixx="{_f(I[0])}" iyy="{_f(I[1])}" izz="{_f(I[2])}" ixy="0" ixz="0" iyz="0"/></inertial>']
        if p.index in visual_files:  # parts without geometry (helper links) get no visual
            fn = f"{mesh_dir}/{visual_files[p.index]}"
            lines += [f'    <visual><origin xyz="{_v(o)}"/><geometry><mesh filename={quoteattr(fn)}/></geometry></visual>',
                      f'    <collision><origin xyz="{_v(o)}"/><geometry><mesh filename={quoteattr(fn)}/></geometry></collision>']
        lines.append("  </link>")
    for j in twin.joints:
        rel = frame[j.child] - frame[j.parent]
        lines += [f"  <joint name={quoteattr(j.name)} type=\"{'continuous' if j.type == 'revolute' and j.limits is None else j.type}\">",
                  f'    <parent link={quoteattr(twin.parts[j.parent].name)}/>',
                  f'    <child link={quoteattr(twin.parts[j.child].name)}/>',
                  f'    <origin xyz="{_v(rel)}" rpy="0 0 0"/>', f'    <axis xyz="{_v(j.axis)}"/>']
        if j.limits is not None:
            lines.append(f'    <limit lower="{_f(j.limits[0])}" upper="{_f(j.limits[1])}" effort="100" velocity="10"/>')
        lines.append("  </joint>")
    lines.append("</robot>")
    return "\n".join(lines) + "\n"

def write_urdf(twin: Twin, path: str | os.PathLike, visual_files: dict[int, str], mesh_dir: str = "visual",
               object_info: dict | None = None) -> None:
    """Write ``twin`` as URDF at ``path`` (atomically); meshes are expected in ``<dir of path>/<mesh_dir>/``."""
    atomic_write_text(path, urdf_text(twin, visual_files, mesh_dir, object_info=object_info))


def parse_object_info(text: Any) -> dict:
    """The object info rsart stored in a twin file (JSON text): only well-formed keys are kept, {} otherwise."""
    try:
        d = json.loads(text) if isinstance(text, str) else None
    except ValueError:
        return {}
    if not isinstance(d, dict):
        return {}
    out: dict = {}
    for k in ("object_id", "category", "units"):
        if isinstance(d.get(k), str) and d[k].strip() and len(d[k]) <= 200:
            out[k] = d[k]
    if "object_id" in out and not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.\-]{0,127}", out["object_id"]):
        del out["object_id"]  # not a safe id: the caller falls back to its default
    if isinstance(d.get("source"), dict) and isinstance(d["source"].get("kind"), str):
        out["source"] = d["source"]
    return out


def read_urdf_object_info(path: str | os.PathLike) -> dict:
    """object_id / category / units / source that rsart stored in a URDF's ``<rsart info=...>`` ({} if none)."""
    import defusedxml.ElementTree as DET

    try:
        root = DET.fromstring(Path(path).read_bytes(), forbid_dtd=True)
    except Exception:  # read_urdf reports bad files; here a missing record is just {}
        return {}
    el = root.find("rsart")
    return parse_object_info(el.get("info")) if el is not None else {}

