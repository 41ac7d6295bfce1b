"""The submission format (``rsart-submission/1``, DESIGN.md §6.2): validation and typed records.

:func:`read_submission` lists *every* problem with its JSON path (``results.door-0001.parts.p1.joint.axis:
zero-length vector``) and returns the parsed :class:`Submission` only when there is none. Files are
untrusted: mesh and image paths must be relative, stay inside the submission file's folder (also after
following symlinks), exist, be regular non-empty files of a known kind within the size limits. Mesh
*content* is parsed later, only from these validated paths (:func:`load_mesh`), and never follows
references to other files (OBJ ``mtllib``, external textures).

Joint convention: ``axis`` (any non-zero length; normalised) and ``origin`` (a point on the axis) are in
the object's world frame **at the ``start`` state** of ``eval_states``; ``values`` are joint values
(rad / scene units) per state id. For joints whose parent is the base (all but chained parts) this frame
equals the rest frame of meta.json.
"""
from __future__ import annotations

import io
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from ..checks import SAFE_ID as _SAFE_VIEW, brief as _brief, is_num as _is_num, kind as _kind
from ..checks import unknown_keys as _keys, vector as _vector
from ..errors import Problem, Problems, RsartError
from ..io import resolve_inside
from .ground_truth import GroundTruth

FORMAT = "rsart-submission/1"
STATIC = "static"
MESH_EXTS = (".ply", ".obj", ".glb")
IMAGE_EXTS = (".png",)
TOP_KEYS = ("format", "method", "dataset", "results")
OBJECT_KEYS = ("parts", "whole", "renders", "masks")
PART_KEYS = ("meshes", "joint")
JOINT_KEYS = ("type", "axis", "origin", "values")
JOINT_TYPES = ("revolute", "prismatic")
MAX_NAME = 128


@dataclass(frozen=True)
class Limits:
    """Size limits for untrusted files (bytes)."""

    max_mesh_bytes: int = 200 * 1024 ** 2
    max_total_bytes: int = 20 * 1024 ** 3
    max_json_bytes: int = 64 * 1024 ** 2
    max_image_bytes: int = 64 * 1024 ** 2


@dataclass
class PredJoint:
    """A predicted joint: unit ``axis`` (3,), ``origin`` (3,) (zeros when a prismatic joint gives none),
    ``values`` state id -> value (rad or scene units); frame: world at the start state."""

    type: str
    axis: np.ndarray
    origin: np.ndarray
    values: dict[str, float]


@dataclass
class PredPart:
    """A predicted part: ``meshes`` state id -> validated absolute path; ``joint`` None for the static part."""

    name: str
    meshes: dict[str, Path]
    joint: PredJoint | None = None
    json_path: str = ""


@dataclass
class PredObject:
    """A predicted object. ``parts[0]`` is the static part; ``whole`` state -> path (optional);
    ``renders``/``masks`` state -> view id -> path (optional). ``mask_label`` part name -> label value."""

    object_id: str
    parts: list[PredPart]
    whole: dict[str, Path] = field(default_factory=dict)
    renders: dict[str, dict[str, Path]] = field(default_factory=dict)
    masks: dict[str, dict[str, Path]] = field(default_factory=dict)

    @property
    def movable(self) -> list[PredPart]:
        return [p for p in self.parts if p.joint is not None]


@dataclass
class Submission:
    """A validated submission. ``results`` maps every object id of the split to a PredObject or None (failed)."""

    path: Path
    root: Path
    method: dict[str, Any]
    dataset: dict[str, Any]
    results: dict[str, PredObject | None]


# ----------------------------------------------------------------------------- JSON
def _reject_constant(name: str) -> Any:
    raise ValueError(f"non-finite number {name} is not allowed (JSON has no NaN/Infinity)")


def _load_json(path: Path, limits: Limits, pb: Problems) -> Any:
    try:
        st = path.stat()
    except OSError:
        pb.add("", f"{path}: submission file not found")
        return None
    if not path.is_file():
        pb.add("", f"{path}: not a file")
        return None
    if st.st_size > limits.max_json_bytes:
        pb.add("", f"{path}: {st.st_size} bytes exceeds the submission-file limit of {limits.max_json_bytes} bytes")
        return None
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as e:
        pb.add("", f"{path}: not UTF-8 text ({e.reason} at byte {e.start})")
        return None
    dups: list[str] = []

    def pairs(items):
        d = {}
        for k, v in items:
            if k in d:
                dups.append(k)
            d[k] = v
        return d

    try:
        data = json.loads(text, parse_constant=_reject_constant, object_pairs_hook=pairs)
    except json.JSONDecodeError as e:
        pb.add("", f"{path}: invalid JSON at line {e.lineno} column {e.colno}: {e.msg}")
        return None
    except ValueError as e:
        pb.add("", f"{path}: {e}")
        return None
    except RecursionError:
        pb.add("", f"{path}: JSON nested too deeply")
        return None
    for k in dups:
        pb.add("", f"duplicate key {k!r} in a JSON object (the value would be ambiguous)")
    return data


# ----------------------------------------------------------------------------- small checks
def _name_ok(pb: Problems, path: str, name: str) -> bool:
    if not name or len(name) > MAX_NAME or any(ord(c) < 32 for c in name):
        pb.add(path, f"name {_brief(name)} must be 1-{MAX_NAME} printable characters")
        return False
    return True


class _Files:
    """Checks untrusted file references against the submission folder and the size limits."""

    def __init__(self, root: Path, limits: Limits, pb: Problems):
        self.root = root
        self.root_r = root.resolve()
        self.limits = limits
        self.pb = pb
        self.total = 0

    def check(self, path: str, rel: Any, exts: tuple[str, ...], max_bytes: int) -> Path | None:
        pb = self.pb
        if not isinstance(rel, str):
            pb.add(path, f"expected a relative file path (string), got {_kind(rel)} {_brief(rel)}")
            return None
        if not rel.strip():
            pb.add(path, "empty path")
            return None
        if os.path.isabs(rel) or rel.startswith(("/", "\\")) or (len(rel) > 1 and rel[1] == ":"):
            pb.add(path, f"{rel!r} is absolute; paths must be relative to the submission file's folder")
            return None
        if ".." in Path(rel.replace("\\", "/")).parts:
            pb.add(path, f"{rel!r} escapes the submission folder ('..')")
            return None
        lexical = self.root / rel
        try:
            target = resolve_inside(self.root, rel)
        except RsartError:
            pb.add(path, f"{rel!r} is a symlink (or passes through one) leading out of the submission folder")
            return None
        except (OSError, RuntimeError) as e:
            pb.add(path, f"{rel!r} cannot be resolved ({e})")
            return None
        if not lexical.exists():
            pb.add(path, f"{rel!r} is missing (no such file in {self.root})")
            return None
        if not target.is_file():
            pb.add(path, f"{rel!r} is not a regular file")
            return None
        ext = target.suffix.lower()
        if Path(rel).suffix.lower() not in exts or ext not in exts:
            pb.add(path, f"{rel!r} is not a supported file kind (expected {', '.join(exts)})")
            return None
        size = target.stat().st_size
        if size == 0:
            pb.add(path, f"{rel!r} is empty (0 bytes)")
            return None
        if size > max_bytes:
            pb.add(path, f"{rel!r} is {size} bytes, over the per-file limit of {max_bytes} bytes")
            return None
        self.total += size
        with open(target, "rb") as f:
            head = f.read(4096)
        if not _magic_ok(ext, head):
            pb.add(path, f"{rel!r} is not a {ext[1:].upper()} file (its content does not match the extension)")
            return None
        return target


def _magic_ok(ext: str, head: bytes) -> bool:
    if ext == ".ply":
        return head.startswith(b"ply")
    if ext == ".glb":
        return head.startswith(b"glTF")
    if ext == ".png":
        return head.startswith(b"\x89PNG\r\n\x1a\n")
    if ext == ".obj":
        if b"\x00" in head:
            return False
        try:
            text = head.decode("utf-8")
        except UnicodeDecodeError:
            return False
        return any(line.lstrip().startswith(("v ", "f ", "#", "o ", "g ", "mtllib", "vn ", "vt "))
                   for line in text.splitlines()[:50])
    return False


# ----------------------------------------------------------------------------- the validator
def read_submission(path: str | os.PathLike, gt: GroundTruth | None, limits: Limits = Limits()
                    ) -> tuple[Submission | None, list[Problem]]:
    """Validate ``path`` (against ``gt`` when given) -> (Submission or None, every problem found)."""
    path = Path(path)
    pb = Problems()
    d = _load_json(path, limits, pb)
    if pb:
        return None, pb.items
    if not isinstance(d, dict):
        return None, [Problem("", f"the submission must be a JSON object, got {_kind(d)}")]
    _keys(pb, "", d, TOP_KEYS)
    for k in TOP_KEYS:
        if k not in d:
            pb.add(k, "missing")
    if "format" in d and d["format"] != FORMAT:
        pb.add("format", f"{_brief(d['format'])} is not {FORMAT!r}")
    method = d.get("method")
    if "method" in d:
        if not isinstance(method, dict):
            pb.add("method", f"expected an object, got {_kind(method)}")
        elif not isinstance(method.get("name"), str) or not method.get("name"):
            pb.add("method.name", "missing or not a non-empty string")
    dataset = d.get("dataset")
    if "dataset" in d:
        if not isinstance(dataset, dict):
            pb.add("dataset", f"expected an object, got {_kind(dataset)}")
        else:
            _keys(pb, "dataset", dataset, ("name", "version", "split"))
            if gt is not None and gt.name is not None:
                if dataset.get("name") != gt.name:
                    pb.add("dataset.name", f"{_brief(dataset.get('name'))} does not match the data ({gt.name!r})")
                if "version" in dataset and str(dataset["version"]) != str(gt.version):
                    pb.add("dataset.version", f"{_brief(dataset['version'])} does not match the data ({gt.version!r})")
    results = d.get("results")
    files = _Files(path.parent, limits, pb)
    parsed: dict[str, PredObject | None] = {}
    if "results" in d:
        if not isinstance(results, dict):
            pb.add("results", f"expected an object mapping object ids to results, got {_kind(results)}")
        else:
            if gt is not None:
                missing = [oid for oid in gt.objects if oid not in results]
                for oid in missing:
                    pb.add(f"results.{oid}", "missing object (every object of the split must appear; use null for a failure)")
            for oid, entry in results.items():
                opath = f"results.{oid}"
                if gt is not None and oid not in gt.objects:
                    pb.add(opath, f"unknown object id (not in the {'split ' + repr(gt.split) if gt.split else 'data'})")
                    continue
                states = None
                ev = None
                if gt is not None:
                    meta = gt.meta(oid)
                    states = [s.id for s in meta.states]
                    ev = meta.eval_states
                parsed[oid] = _object(pb, files, opath, oid, entry, states, ev, limits)
    if files.total > limits.max_total_bytes:
        pb.add("results", f"referenced files total {files.total} bytes, over the limit of {limits.max_total_bytes}")
    if pb:
        return None, pb.items
    return Submission(path, path.parent, dict(method), dict(dataset), parsed), []


def _state_ok(pb: Problems, path: str, sid: Any, states: list[str] | None) -> bool:
    if not isinstance(sid, str) or not sid:
        pb.add(path, f"expected a state id, got {_brief(sid)}")
        return False
    if states is not None and sid not in states:
        pb.add(path, f"unknown state {sid!r} (states: {', '.join(states)})")
        return False
    return True


def _file_map(pb: Problems, files: _Files, path: str, v: Any, states: list[str] | None,
              exts: tuple[str, ...], max_bytes: int) -> dict[str, Path]:
    out: dict[str, Path] = {}
    if not isinstance(v, dict):
        pb.add(path, f"expected an object state id -> file path, got {_kind(v)}")
        return out
    for sid, rel in v.items():
        if _state_ok(pb, f"{path}.{sid}", sid, states):
            p = files.check(f"{path}.{sid}", rel, exts, max_bytes)
            if p is not None:
                out[sid] = p
    return out


def _views_map(pb: Problems, files: _Files, path: str, v: Any, states: list[str] | None,
               limits: Limits) -> dict[str, dict[str, Path]]:
    out: dict[str, dict[str, Path]] = {}
    if not isinstance(v, dict):
        pb.add(path, f"expected an object state id -> {{view id -> PNG path}}, got {_kind(v)}")
        return out
    for sid, views in v.items():
        if not _state_ok(pb, f"{path}.{sid}", sid, states):
            continue
        if not isinstance(views, dict):
            pb.add(f"{path}.{sid}", f"expected an object view id -> PNG path, got {_kind(views)}")
            continue
        out[sid] = {}
        for vid, rel in views.items():
            if not _SAFE_VIEW.match(vid):
                pb.add(f"{path}.{sid}.{vid}", "view id must be letters, digits, '_', '.', '-' (it names a dataset file)")
                continue
            p = files.check(f"{path}.{sid}.{vid}", rel, IMAGE_EXTS, limits.max_image_bytes)
            if p is not None:
                out[sid][vid] = p
    return out


def _object(pb: Problems, files: _Files, opath: str, oid: str, entry: Any, states: list[str] | None,
            ev: dict[str, str] | None, limits: Limits) -> PredObject | None:
    if entry is None:
        return None
    if not isinstance(entry, dict):
        pb.add(opath, f"expected an object (or null for a failure), got {_kind(entry)}")
        return None
    _keys(pb, opath, entry, OBJECT_KEYS)
    parts_d = entry.get("parts")
    parts: list[PredPart] = []
    if "parts" not in entry:
        pb.add(f"{opath}.parts", "missing")
    elif not isinstance(parts_d, dict) or not parts_d:
        pb.add(f"{opath}.parts", f"expected a non-empty object part name -> part, got {_kind(parts_d)}")
    else:
        if STATIC not in parts_d:
            pb.add(f"{opath}.parts", f"no {STATIC!r} part (the static base must be given)")
        for name, part in parts_d.items():
            ppath = f"{opath}.parts.{name}"
            if not _name_ok(pb, ppath, name):
                continue
            pp = _part(pb, files, ppath, name, part, states, ev, limits)
            if pp is not None:
                parts.append(pp)
        parts.sort(key=lambda p: p.name != STATIC)  # static first, others in JSON order
    whole = _file_map(pb, files, f"{opath}.whole", entry["whole"], states, MESH_EXTS, limits.max_mesh_bytes) \
        if "whole" in entry else {}
    renders = _views_map(pb, files, f"{opath}.renders", entry["renders"], states, limits) if "renders" in entry else {}
    masks = _views_map(pb, files, f"{opath}.masks", entry["masks"], states, limits) if "masks" in entry else {}
    return PredObject(oid, parts, whole, renders, masks)


def _part(pb: Problems, files: _Files, ppath: str, name: str, part: Any, states: list[str] | None,
          ev: dict[str, str] | None, limits: Limits) -> PredPart | None:
    if not isinstance(part, dict):
        pb.add(ppath, f"expected an object with 'meshes' and (movable parts) 'joint', got {_kind(part)}")
        return None
    _keys(pb, ppath, part, PART_KEYS)
    meshes = _file_map(pb, files, f"{ppath}.meshes", part["meshes"], states, MESH_EXTS, limits.max_mesh_bytes) \
        if "meshes" in part else {}
    joint = None
    if name == STATIC:
        if "joint" in part:
            pb.add(f"{ppath}.joint", "the static part has no joint")
    elif "joint" not in part:
        pb.add(f"{ppath}.joint", "missing (every part other than 'static' is movable and needs a joint)")
    else:
        joint = _joint(pb, f"{ppath}.joint", part["joint"], states, ev)
    return PredPart(name, meshes, joint, ppath)


def _joint(pb: Problems, jpath: str, j: Any, states: list[str] | None, ev: dict[str, str] | None) -> PredJoint | None:
    if not isinstance(j, dict):
        pb.add(jpath, f"expected an object, got {_kind(j)}")
        return None
    n0 = len(pb)
    _keys(pb, jpath, j, JOINT_KEYS)
    for k in ("type", "axis", "values"):
        if k not in j:
            pb.add(f"{jpath}.{k}", "missing")
    t = j.get("type")
    if "type" in j and t not in JOINT_TYPES:
        pb.add(f"{jpath}.type", f"{_brief(t)} is not one of {list(JOINT_TYPES)}")
    axis = _vector(pb, f"{jpath}.axis", j["axis"], nonzero=True) if "axis" in j else None
    origin = None
    if "origin" in j:
        origin = _vector(pb, f"{jpath}.origin", j["origin"], nonzero=False)
    elif t == "revolute":
        pb.add(f"{jpath}.origin", "missing (a revolute joint needs a point on its axis)")
    values: dict[str, float] = {}
    v = j.get("values")
    if "values" in j:
        if not isinstance(v, dict):
            pb.add(f"{jpath}.values", f"expected an object state id -> value, got {_kind(v)}")
        else:
            for sid, x in v.items():
                vp = f"{jpath}.values.{sid}"
                if not _state_ok(pb, vp, sid, states):
                    continue
                if not _is_num(x):
                    pb.add(vp, f"expected a number, got {_kind(x)} {_brief(x)}")
                elif not math.isfinite(x):
                    pb.add(vp, "non-finite number")
                else:
                    values[sid] = float(x)
            if ev is not None:
                for k in ("start", "end"):
                    if ev[k] not in v:
                        pb.add(f"{jpath}.values", f"no value for the {k} state {ev[k]!r} (Part Motion needs it)")
    if len(pb) > n0:
        return None
    return PredJoint(t, axis / np.linalg.norm(axis), origin if origin is not None else np.zeros(3), values)


# ----------------------------------------------------------------------------- mesh content
class MeshError(RsartError):
    """A validated mesh file whose content is not a usable triangle mesh."""


def load_mesh(path: Path, max_bytes: int = Limits().max_mesh_bytes) -> trimesh.Trimesh:
    """Parse a validated mesh file (PLY/OBJ/GLB) as one geometry-only triangle mesh.

    Parsed from bytes with no file resolver, so references inside the file (OBJ ``mtllib``, external
    textures) are never followed. Raises MeshError on unparseable content, no faces or non-finite vertices.
    """
    size = path.stat().st_size
    if size > max_bytes:
        raise MeshError(f"{size} bytes, over the per-file limit of {max_bytes}")
    data = path.read_bytes()
    ext = path.suffix.lower().lstrip(".")
    try:
        loaded = trimesh.load(io.BytesIO(data), file_type=ext, force="mesh", process=False)
    except Exception as e:  # any parser failure of untrusted content is a content problem
        raise MeshError(f"cannot be parsed as {ext.upper()} ({type(e).__name__}: {str(e)[:120]})") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise MeshError("contains no triangles")
    v = np.asarray(loaded.vertices, dtype=np.float64)
    f = np.asarray(loaded.faces, dtype=np.int64)
    if not np.all(np.isfinite(v)):
        raise MeshError("has non-finite vertex coordinates")
    if f.min() < 0 or f.max() >= len(v):
        raise MeshError("has faces indexing missing vertices")
    return trimesh.Trimesh(v, f, process=False)
