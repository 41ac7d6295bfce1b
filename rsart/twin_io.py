"""The one writer (and reader) of an object folder's twin.

``write_object`` turns a :class:`~rsart.kinematics.Twin` into the object folder of
docs/format.md (meta.json, watertight part PLYs, textured visual OBJs, URDF, USD), built in
a temporary folder and renamed into place when complete. ``read_twin`` rebuilds the Twin from
``meta.json`` (the source of truth for joints) and the part meshes.
"""
from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import trimesh

from .atlas import merge_visuals
from .errors import RsartError
from .format import FORMAT, ObjectMeta, State, read_meta, write_meta
from .io import atomic_dir, atomic_write_bytes, resolve_inside
from .kinematics import Twin, TwinPart
from .states import protocol_states
from .urdf import load_mesh_file, write_urdf

PARTS_DIR = "twin/parts"
VISUAL_DIR = "twin/visual"
URDF_PATH = "twin/object.urdf"
USD_PATH = "twin/object.usda"


def _export_visual(part: TwinPart, folder: Path) -> str | None:
    """Write a part's render meshes as ``<name>.obj`` (+ .mtl and textures) into ``folder``; returns the file name."""
    meshes = [m for m in part.render_meshes() if len(m.faces)]
    if not meshes:
        return None
    mesh = meshes[0].copy() if len(meshes) == 1 else merge_visuals(meshes)
    mat = getattr(mesh.visual, "material", None)
    if mat is not None:
        mat.name = part.name
    text, files = trimesh.exchange.obj.export_obj(mesh, include_normals=False, include_texture=True,
                                                  return_texture=True, mtl_name=f"{part.name}.mtl")
    # trimesh names textures after the material; give them part-unique names
    renames = {}
    for fname in list(files):
        if fname.endswith(".mtl"):
            continue
        new = f"{part.name}_{fname}" if not fname.startswith(part.name) else fname
        renames[fname] = new
    for fname, data in files.items():
        if fname.endswith(".mtl"):
            mtl = data.decode("utf-8")
            for old, new in renames.items():
                mtl = re.sub(rf"(?m)^(\s*map_\w+\s+){re.escape(old)}\s*$", rf"\g<1>{new}", mtl)
            atomic_write_bytes(folder / fname, mtl.encode("utf-8"))
        else:
            atomic_write_bytes(folder / renames[fname], data)
    atomic_write_bytes(folder / f"{part.name}.obj", text.encode("utf-8"))
    return f"{part.name}.obj"


def write_object(twin: Twin, out_dir: str | os.PathLike, *, object_id: str, category: str,
                 source: dict[str, Any], units: str = "m", states: list[State] | None = None,
                 eval_states: dict[str, str] | None = None, extra_meta: dict[str, Any] | None = None,
                 overwrite: bool = False, write_usd: bool = True) -> ObjectMeta:
    """Write ``twin`` as a complete object folder at ``out_dir`` (atomically) and return its meta.

    ``states`` default to the RS-Art protocol (:func:`rsart.states.protocol_states`).
    """
    if states is None:
        states, ev = protocol_states(twin.joints)
        eval_states = eval_states or ev
    parts = twin.to_parts(PARTS_DIR)
    # kept inside the URDF and USD so that converting either back keeps the object's identity
    info = {"object_id": object_id, "category": category, "units": units, "source": dict(source)}
    with atomic_dir(out_dir, overwrite=overwrite) as tmp:
        (tmp / PARTS_DIR).mkdir(parents=True)
        (tmp / VISUAL_DIR).mkdir(parents=True)
        visual_files = {}
        for p, rec in zip(twin.parts, parts):
            geom = trimesh.Trimesh(p.mesh.vertices, p.mesh.faces, process=False)
            atomic_write_bytes(tmp / rec.mesh, trimesh.exchange.ply.export_ply(geom, encoding="binary"))
            vf = _export_visual(p, tmp / VISUAL_DIR)
            if vf is not None:
                visual_files[p.index] = vf
                rec.extra["visual"] = f"{VISUAL_DIR}/{vf}"
        write_urdf(twin, tmp / URDF_PATH, visual_files, mesh_dir="visual", object_info=info)
        twin_files = {"urdf": URDF_PATH}
        if write_usd:
            from .extras import has

            if has("usd"):  # without the [usd] extra the URDF alone describes the twin (docs/procedural.md)
                from . import usd

                usd.write_usd(twin, tmp / USD_PATH, units=units, object_info=info)
                twin_files["usd"] = USD_PATH
        meta = ObjectMeta(object_id=object_id, category=category, source=dict(source), units=units,
                          twin=twin_files, parts=parts, joints=list(twin.joints), states=list(states),
                          eval_states=dict(eval_states or {"start": states[0].id, "end": states[-1].id}),
                          format=FORMAT, extra=dict(extra_meta or {}))
        write_meta(meta, tmp / "meta.json")
    return meta


def read_twin(obj_dir: str | os.PathLike, meta: ObjectMeta | None = None, visuals: bool = True) -> Twin:
    """Rebuild the :class:`Twin` of an object folder from meta.json and its meshes (paths kept inside the folder)."""
    obj_dir = Path(obj_dir)
    meta = meta or read_meta(obj_dir)
    parts = []
    for p in meta.parts:
        path = resolve_inside(obj_dir, p.mesh)
        if not path.is_file():
            raise RsartError(f"{obj_dir / 'meta.json'}: parts[{p.index}].mesh: file {p.mesh!r} not found")
        ms = load_mesh_file(path)
        geom = ms[0] if len(ms) == 1 else trimesh.util.concatenate(ms)
        vis: list[trimesh.Trimesh] = []
        vpath = p.extra.get("visual")
        if visuals and isinstance(vpath, str):
            vp = resolve_inside(obj_dir, vpath)
            if vp.is_file():
                vis = load_mesh_file(vp)
        parts.append(TwinPart(p.index, p.name, geom, vis, {k: v for k, v in p.extra.items() if k != "visual"}))
    return Twin(meta.object_id, parts, [j for j in meta.joints])
