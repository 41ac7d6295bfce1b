"""The RS-Art on-disk format (``rsart/1``): typed records, readers that validate, writers.

This module is the one place that reads and writes ``meta.json``, ``cameras.json`` and
``index.json`` (documented for users in docs/format.md). Readers check *everything* and
raise one :class:`~rsart.errors.ValidationError` listing every problem with its JSON path.

Units and frames: metres (or unitless "scene" units, see ``ObjectMeta.units``) and
radians; joint ``axis``/``origin`` in the world (object base) frame with every joint at 0;
camera ``c2w`` camera-to-world with OpenCV axes.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .camera import Camera, Intrinsics
from .checks import brief as _brief, extra as _extra, is_finite_num as _num, is_int as _is_int
from .checks import mapping as _dict, relpath as _relpath, string as _str, unique_id as _unique_id, vector as _vec
from .errors import Problems, RsartError, ValidationError
from .io import check_inside, read_json, write_json

FORMAT = "rsart/1"
JOINT_TYPES = ("revolute", "prismatic")
STATE_KINDS = ("multi", "single")
SPLITS = ("train", "test")
UNITS = ("m", "scene")
SOURCE_KINDS = ("procedural", "partnet-mobility", "rs-art", "urdf", "usd")


# ----------------------------------------------------------------------------- records
@dataclass
class Part:
    """A rigid part; ``index`` 0 is the static base. ``mesh`` is the watertight PLY, relative to the object folder."""

    index: int
    name: str
    mesh: str
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass
class Joint:
    """A 1-DoF joint moving part ``child`` relative to part ``parent``.

    ``axis`` (3,) unit vector and ``origin`` (3,) point on the axis, world frame, all joints at 0.
    ``limits`` = (lower, upper) in radians (revolute) or metres (prismatic), or None (unlimited revolute).
    """

    name: str
    type: str
    parent: int
    child: int
    axis: np.ndarray
    origin: np.ndarray
    limits: tuple[float, float] | None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def range(self) -> float:
        """upper - lower (0 when unlimited)."""
        return 0.0 if self.limits is None else self.limits[1] - self.limits[0]


@dataclass
class State:
    """An interaction state: ``values`` maps every joint name to its value (rad or m).

    ``kind`` is "multi" (all movable parts together) or "single" (``joint`` at its ``extreme`` "min"|"max").
    """

    id: str
    kind: str
    values: dict[str, float]
    joint: str | None = None
    extreme: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass
class ObjectMeta:
    """Contents of one object's ``meta.json``."""

    object_id: str
    category: str
    source: dict[str, Any]
    units: str
    twin: dict[str, str]
    parts: list[Part]
    joints: list[Joint]
    states: list[State]
    eval_states: dict[str, str]
    format: str = FORMAT
    extra: dict[str, Any] = field(default_factory=dict)

    def state(self, state_id: str) -> State:
        for s in self.states:
            if s.id == state_id:
                return s
        raise KeyError(f"{self.object_id}: no state {state_id!r} (states: {[s.id for s in self.states]})")

    def joint(self, name: str) -> Joint:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(f"{self.object_id}: no joint {name!r}")

    @property
    def movable_parts(self) -> list[Part]:
        return [p for p in self.parts if p.index != 0]


@dataclass
class ViewRecord:
    """One view of ``cameras.json``: ``c2w`` (4, 4) camera-to-world, OpenCV axes; ``split`` train|test."""

    id: str
    c2w: np.ndarray
    split: str
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass
class CamerasFile:
    """Contents of a state's ``cameras.json``: shared intrinsics, depth scale (m per unit), views."""

    intrinsics: Intrinsics
    depth_scale: float
    views: list[ViewRecord]
    extra: dict[str, Any] = field(default_factory=dict)

    def camera(self, i: int) -> Camera:
        return Camera(self.intrinsics, self.views[i].c2w)


@dataclass
class DatasetIndex:
    """Contents of a dataset root's ``index.json``."""

    name: str
    version: str
    objects: list[str]
    splits: dict[str, list[str]]
    format: str = FORMAT
    extra: dict[str, Any] = field(default_factory=dict)


# ----------------------------------------------------------------------------- meta.json
_META_KEYS = ("format", "object_id", "category", "source", "units", "twin", "parts", "joints", "states", "eval_states")


def parse_meta(d: Any, source: str | None = None) -> ObjectMeta:
    """Validate a decoded ``meta.json`` and build an :class:`ObjectMeta` (raises ValidationError listing every problem)."""
    pb = Problems()
    if not _dict(pb, "", d, _META_KEYS[:-1]):
        pb.raise_if_any(source)
    if "format" in d and (not isinstance(d["format"], str) or not d["format"].startswith("rsart/1")):
        pb.add("format", f"unsupported format {_brief(d['format'])} (expected {FORMAT!r})")
    if "object_id" in d:
        _str(pb, "object_id", d["object_id"], safe=True)
    if "category" in d:
        _str(pb, "category", d["category"])
    if "source" in d and _dict(pb, "source", d["source"], ("kind",)) and "kind" in d["source"]:
        if d["source"]["kind"] not in SOURCE_KINDS:
            pb.add("source.kind", f"{_brief(d['source']['kind'])} is not one of {list(SOURCE_KINDS)}")
    if "units" in d and d["units"] not in UNITS:
        pb.add("units", f"{_brief(d['units'])} is not one of {list(UNITS)}")
    if "twin" in d and _dict(pb, "twin", d["twin"], ()):
        for k, v in d["twin"].items():
            _relpath(pb, f"twin.{k}", v)

    parts = _parse_parts(pb, d.get("parts"))
    joints = _parse_joints(pb, d.get("joints"), len(parts) if parts is not None else None)
    states = _parse_states(pb, d.get("states"), joints)
    ev = d.get("eval_states")
    if ev is not None and _dict(pb, "eval_states", ev, ("start", "end")) and states is not None:
        ids = {s.id for s in states}
        for k in ("start", "end"):
            if k in ev and ev[k] not in ids:
                pb.add(f"eval_states.{k}", f"unknown state {_brief(ev[k])}")
    pb.raise_if_any(source)
    if ev is None and states:
        multi = [s.id for s in states if s.kind == "multi"] or [s.id for s in states]
        ev = {"start": multi[0], "end": multi[-1]}
    return ObjectMeta(object_id=d["object_id"], category=d["category"], source=dict(d["source"]),
                      units=d["units"], twin=dict(d["twin"]), parts=parts, joints=joints, states=states,
                      eval_states=dict(ev), format=d["format"], extra=_extra(d, _META_KEYS))


def _parse_parts(pb: Problems, v: Any) -> list[Part] | None:
    if not isinstance(v, list) or not v:
        pb.add("parts", f"expected a non-empty list of parts, got {_brief(v)}")
        return None
    parts, names = [], set()
    for i, p in enumerate(v):
        path = f"parts[{i}]"
        if not _dict(pb, path, p, ("index", "name", "mesh")):
            continue
        if "index" in p and p["index"] != i:
            pb.add(f"{path}.index", f"must equal its position {i}, got {_brief(p['index'])}")
        if "name" in p:
            _unique_id(pb, f"{path}.name", p["name"], names, "part name")
        if "mesh" in p:
            _relpath(pb, f"{path}.mesh", p["mesh"])
        parts.append(Part(i, p.get("name", ""), p.get("mesh", ""), _extra(p, ("index", "name", "mesh"))))
    return parts


_JOINT_KEYS = ("name", "type", "parent", "child", "axis", "origin", "limits")


def _parse_joints(pb: Problems, v: Any, n_parts: int | None) -> list[Joint] | None:
    if not isinstance(v, list):
        pb.add("joints", f"expected a list, got {_brief(v)}")
        return None
    joints: list[Joint] = []
    names: set[str] = set()
    child_of: dict[int, int] = {}
    for i, j in enumerate(v):
        path = f"joints[{i}]"
        if not _dict(pb, path, j, _JOINT_KEYS):
            continue
        ok = "name" in j and _unique_id(pb, f"{path}.name", j["name"], names, "joint name")
        if j.get("type") not in JOINT_TYPES:
            pb.add(f"{path}.type", f"{_brief(j.get('type'))} is not one of {list(JOINT_TYPES)}")
            ok = False
        for k in ("parent", "child"):
            x = j.get(k)
            if not _is_int(x) or x < 0 or (n_parts is not None and x >= n_parts):
                pb.add(f"{path}.{k}", f"expected a part index in [0, {(n_parts or 1) - 1}], got {_brief(x)}")
                ok = False
        if ok:
            if j["child"] == 0:
                pb.add(f"{path}.child", "part 0 is the static base and cannot be a joint's child")
            elif j["child"] in child_of:
                pb.add(f"{path}.child", f"part {j['child']} is already the child of joints[{child_of[j['child']]}]")
            else:
                child_of[j["child"]] = i
            if j["parent"] == j["child"]:
                pb.add(f"{path}.parent", "a joint's parent and child must differ")
        axis = _vec(pb, f"{path}.axis", j.get("axis"), 3, unit=True) if "axis" in j else None
        origin = _vec(pb, f"{path}.origin", j.get("origin"), 3) if "origin" in j else None
        limits = None
        lim = j.get("limits")
        if lim is not None:
            if not isinstance(lim, list) or len(lim) != 2 or not all(_num(x) for x in lim):
                pb.add(f"{path}.limits", f"expected [lower, upper] finite numbers or null, got {_brief(lim)}")
            elif lim[0] > lim[1]:
                pb.add(f"{path}.limits", f"lower {lim[0]} > upper {lim[1]}")
            else:
                limits = (float(lim[0]), float(lim[1]))
        elif j.get("type") == "prismatic" and "limits" in j:
            pb.add(f"{path}.limits", "a prismatic joint needs limits")
        joints.append(Joint(j.get("name", ""), j.get("type", ""), j.get("parent", -1), j.get("child", -1),
                            axis if axis is not None else np.array([0.0, 0.0, 1.0]),
                            origin if origin is not None else np.zeros(3), limits, _extra(j, _JOINT_KEYS)))
    if n_parts is not None:
        for p in range(1, n_parts):
            if p not in child_of:
                pb.add("joints", f"part {p} is not the child of any joint (every movable part needs exactly one)")
        # cycles: following parents from any part must reach 0
        parent = {joints[ji].child: joints[ji].parent for ji in child_of.values()}
        for p in parent:
            seen, q = set(), p
            while q != 0 and q in parent and q not in seen:
                seen.add(q)
                q = parent[q]
            if q != 0:
                pb.add(f"joints[{child_of[p]}]", f"part {p} does not lead back to the base (cycle or dangling parent)")
                break
    return joints


def _parse_states(pb: Problems, v: Any, joints: list[Joint] | None) -> list[State] | None:
    if not isinstance(v, list) or not v:
        pb.add("states", f"expected a non-empty list of states, got {_brief(v)}")
        return None
    jmap = {j.name: j for j in joints or []}
    states, ids = [], set()
    for i, s in enumerate(v):
        path = f"states[{i}]"
        if not _dict(pb, path, s, ("id", "kind", "values")):
            continue
        if "id" in s:
            _unique_id(pb, f"{path}.id", s["id"], ids, "state id")
        if s.get("kind") not in STATE_KINDS:
            pb.add(f"{path}.kind", f"{_brief(s.get('kind'))} is not one of {list(STATE_KINDS)}")
        vals = s.get("values")
        values: dict[str, float] = {}
        if isinstance(vals, dict):
            for name, x in vals.items():
                if joints is not None and name not in jmap:
                    pb.add(f"{path}.values.{name}", "unknown joint")
                elif not _num(x):
                    pb.add(f"{path}.values.{name}", f"expected a finite number, got {_brief(x)}")
                else:
                    values[name] = float(x)
                    lim = jmap[name].limits if name in jmap else None
                    if lim is not None and not (lim[0] - 1e-9 <= x <= lim[1] + 1e-9):
                        pb.add(f"{path}.values.{name}", f"{x} outside the joint limits {list(lim)}")
            for name in jmap:
                if name not in vals:
                    pb.add(f"{path}.values.{name}", "missing (every state gives a value for every joint)")
        elif "values" in s:
            pb.add(f"{path}.values", f"expected an object joint name -> value, got {_brief(vals)}")
        if s.get("kind") == "single":
            if s.get("joint") not in jmap and joints is not None:
                pb.add(f"{path}.joint", f"a single state names the joint that moves; {_brief(s.get('joint'))} is not a joint")
            if s.get("extreme") not in ("min", "max"):
                pb.add(f"{path}.extreme", f"expected 'min' or 'max', got {_brief(s.get('extreme'))}")
        states.append(State(s.get("id", ""), s.get("kind", ""), values, s.get("joint"), s.get("extreme"),
                            _extra(s, ("id", "kind", "values", "joint", "extreme"))))
    return states


def meta_to_dict(m: ObjectMeta) -> dict:
    """The JSON-ready dict of an :class:`ObjectMeta` (keys in contract order, floats only)."""
    return {
        "format": m.format, "object_id": m.object_id, "category": m.category, "source": m.source,
        "units": m.units, "twin": m.twin,
        "parts": [{"index": p.index, "name": p.name, "mesh": p.mesh, **p.extra} for p in m.parts],
        "joints": [{"name": j.name, "type": j.type, "parent": j.parent, "child": j.child,
                    "axis": [float(x) for x in j.axis], "origin": [float(x) for x in j.origin],
                    "limits": None if j.limits is None else [float(j.limits[0]), float(j.limits[1])], **j.extra}
                   for j in m.joints],
        "states": [{"id": s.id, "kind": s.kind, **({"joint": s.joint, "extreme": s.extreme} if s.kind == "single" else {}),
                    "values": {k: float(v) for k, v in s.values.items()}, **s.extra} for s in m.states],
        "eval_states": m.eval_states, **m.extra,
    }


def _in_folder(path: str | Path, name: str) -> Path:
    """``path``, or ``path/name`` when ``path`` is a folder."""
    path = Path(path)
    return path / name if path.is_dir() else path


def read_meta(path: str | Path) -> ObjectMeta:
    """Read and validate ``meta.json`` (a file, or an object folder containing one)."""
    path = _in_folder(path, "meta.json")
    return parse_meta(read_json(path), source=str(path))


def write_meta(meta: ObjectMeta, path: str | Path) -> None:
    """Validate and atomically write ``meta.json`` (``path`` may be the object folder)."""
    path = Path(path)
    if path.is_dir() or path.suffix != ".json":
        path = path / "meta.json"
    d = meta_to_dict(meta)
    parse_meta(d, source=str(path))  # never write what we could not read back
    write_json(path, d)


# ----------------------------------------------------------------------------- cameras.json
def parse_cameras(d: Any, source: str | None = None) -> CamerasFile:
    """Validate a decoded ``cameras.json`` and build a :class:`CamerasFile`."""
    pb = Problems()
    if not _dict(pb, "", d, ("intrinsics", "depth_scale", "views")):
        pb.raise_if_any(source)
    intr = None
    k = d.get("intrinsics")
    if k is not None and _dict(pb, "intrinsics", k, ("width", "height", "fx", "fy", "cx", "cy")):
        for key in ("width", "height"):
            if key in k and (not _is_int(k[key]) or not 0 < k[key] <= 100000):
                pb.add(f"intrinsics.{key}", f"expected a positive integer, got {_brief(k[key])}")
        for key in ("fx", "fy"):
            if key in k and (not _num(k[key]) or k[key] <= 0):
                pb.add(f"intrinsics.{key}", f"expected a positive finite number, got {_brief(k[key])}")
        for key in ("cx", "cy"):
            if key in k and not _num(k[key]):
                pb.add(f"intrinsics.{key}", f"expected a finite number, got {_brief(k[key])}")
        dist = k.get("distortion")
        if dist is not None and (not isinstance(dist, list) or not all(_num(x) for x in dist)):
            pb.add("intrinsics.distortion", f"expected null or a list of finite numbers, got {_brief(dist)}")
        if not pb:
            intr = Intrinsics(k["width"], k["height"], float(k["fx"]), float(k["fy"]), float(k["cx"]),
                              float(k["cy"]), tuple(float(x) for x in dist) if dist else None)
    ds = d.get("depth_scale")
    if "depth_scale" in d and (not _num(ds) or ds <= 0):
        pb.add("depth_scale", f"expected a positive number of metres per depth unit, got {_brief(ds)}")
    views, ids = [], set()
    vs = d.get("views")
    if "views" in d and not isinstance(vs, list):
        pb.add("views", f"expected a list, got {_brief(vs)}")
        vs = []
    for i, v in enumerate(vs or []):
        path = f"views[{i}]"
        if not _dict(pb, path, v, ("id", "c2w", "split")):
            continue
        if "id" in v:
            _unique_id(pb, f"{path}.id", v["id"], ids, "view id")
        c2w = _matrix(pb, f"{path}.c2w", v.get("c2w")) if "c2w" in v else None
        if "split" in v and v["split"] not in SPLITS:
            pb.add(f"{path}.split", f"{_brief(v['split'])} is not one of {list(SPLITS)}")
        views.append(ViewRecord(v.get("id", ""), c2w if c2w is not None else np.eye(4), v.get("split", "train"),
                                _extra(v, ("id", "c2w", "split"))))
    pb.raise_if_any(source)
    return CamerasFile(intr, float(ds), views, _extra(d, ("intrinsics", "depth_scale", "views")))


def _matrix(pb: Problems, path: str, m: Any) -> np.ndarray | None:
    if not isinstance(m, list) or len(m) != 4 or not all(isinstance(r, list) and len(r) == 4 for r in m):
        pb.add(path, "expected a 4x4 matrix (list of 4 rows of 4 numbers)")
        return None
    if not all(_num(x) for r in m for x in r):
        pb.add(path, "expected finite numbers")
        return None
    a = np.asarray(m, dtype=np.float64)
    if not np.allclose(a[3], [0, 0, 0, 1], atol=1e-9):
        pb.add(path, "last row must be [0, 0, 0, 1]")
        return None
    R = a[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
        pb.add(path, "rotation block is not a proper rotation (orthonormal, det +1)")
        return None
    return a


def read_cameras(path: str | Path) -> CamerasFile:
    """Read and validate a state's ``cameras.json``."""
    path = Path(path)
    return parse_cameras(read_json(path), source=str(path))


def cameras_to_dict(c: CamerasFile) -> dict:
    return {"intrinsics": c.intrinsics.to_dict(), "depth_scale": float(c.depth_scale),
            "views": [{"id": v.id, "c2w": np.asarray(v.c2w, dtype=float).tolist(), "split": v.split, **v.extra}
                      for v in c.views], **c.extra}


def write_cameras(cams: CamerasFile, path: str | Path) -> None:
    """Validate and atomically write ``cameras.json``."""
    d = cameras_to_dict(cams)
    parse_cameras(d, source=str(path))  # never write what we could not read back
    write_json(path, d)


# ----------------------------------------------------------------------------- index.json
def parse_index(d: Any, source: str | None = None) -> DatasetIndex:
    """Validate a decoded ``index.json``."""
    pb = Problems()
    if not _dict(pb, "", d, ("format", "name", "version", "objects", "splits")):
        pb.raise_if_any(source)
    if "format" in d and (not isinstance(d["format"], str) or not d["format"].startswith("rsart/1")):
        pb.add("format", f"unsupported format {_brief(d['format'])}")
    if "name" in d:
        _str(pb, "name", d["name"])
    objs = d.get("objects")
    if "objects" in d:
        if not isinstance(objs, list):
            pb.add("objects", "expected a list of object ids")
            objs = []
        for i, o in enumerate(objs):
            _str(pb, f"objects[{i}]", o, safe=True)
        if len(set(map(str, objs))) != len(objs):
            pb.add("objects", "duplicate object ids")
    splits = d.get("splits")
    if "splits" in d and _dict(pb, "splits", splits, ()):
        known = set(map(str, objs or []))
        for name, ids in splits.items():
            if not isinstance(ids, list):
                pb.add(f"splits.{name}", "expected a list of object ids")
                continue
            for i, o in enumerate(ids):
                if o not in known:
                    pb.add(f"splits.{name}[{i}]", f"{_brief(o)} is not in objects")
    pb.raise_if_any(source)
    return DatasetIndex(d["name"], str(d["version"]), list(objs), {k: list(v) for k, v in splits.items()},
                        d["format"], _extra(d, ("format", "name", "version", "objects", "splits")))


def read_index(path: str | Path) -> DatasetIndex:
    """Read and validate ``index.json`` (a file, or a dataset root containing one)."""
    path = _in_folder(path, "index.json")
    return parse_index(read_json(path), source=str(path))


def write_index(index: DatasetIndex, path: str | Path) -> None:
    """Validate and atomically write ``index.json`` (``path`` may be the dataset root)."""
    path = _in_folder(path, "index.json")
    d = {"format": index.format, "name": index.name, "version": index.version,
         "objects": index.objects, "splits": index.splits, **index.extra}
    parse_index(d, source=str(path))  # never write what we could not read back
    write_json(path, d)


def validate_path(path: str | Path, root: str | Path | None = None) -> list[str]:
    """Validate a meta.json, cameras.json, index.json, an object folder or a dataset root.

    Returns the list of problem lines (empty when valid); used by ``rsart validate``. Nothing outside
    ``root`` (default: ``path`` itself, or its folder for a file) is read: a file or state folder whose
    symlinks lead out of it is reported without being opened or listed (:func:`rsart.io.check_inside`).
    """
    path = Path(path)
    root = Path(root) if root is not None else (path.parent if path.is_file() else path)
    out: list[str] = []

    def run(fn, p):
        try:
            fn(check_inside(root, p))
        except ValidationError as e:
            out.extend(f"{p}: {x}" for x in e.problems)
        except RsartError as e:
            out.append(str(e))

    if path.is_file():
        reader = {"meta.json": read_meta, "cameras.json": read_cameras, "index.json": read_index}.get(path.name)
        if reader is None:
            return [f"{path}: not a meta.json, cameras.json or index.json"]
        run(reader, path)
    elif (path / "index.json").exists():
        run(read_index, path / "index.json")
        if not out:
            for oid in read_index(path).objects:
                try:
                    out.extend(validate_path(check_inside(root, path / oid), root))
                except RsartError as e:
                    out.append(str(e))
    elif (path / "meta.json").exists():
        run(read_meta, path / "meta.json")
        states = path / "states"
        try:
            subdirs = sorted(d for d in check_inside(root, states).iterdir()) if states.is_dir() else []
        except RsartError as e:
            out.append(str(e))
            subdirs = []
        for d in subdirs:  # each state folder is checked before anything in it is listed or read
            try:
                check_inside(root, d)
            except RsartError as e:
                out.append(str(e))
                continue
            if (d / "cameras.json").is_file():
                run(read_cameras, d / "cameras.json")
    else:
        out.append(f"{path}: neither a dataset root (index.json) nor an object folder (meta.json)")
    return out
