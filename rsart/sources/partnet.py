"""PartNet-Mobility objects -> RS-Art object folders (``rsart convert partnet-mobility``).

Input: one PartNet-Mobility object folder (``mobility.urdf``, ``meta.json``, ``semantics.txt``,
``mobility_v2.json``, ``textured_objs/``), all treated as untrusted. The URDF is the source of truth
for parts and joints; ``mobility_v2.json`` is only cross-checked and recorded.

* Parts: links merged across fixed joints (:func:`rsart.urdf.read_urdf`); the helper link of a
  prismatic + continuous screw is folded (:func:`rsart.sources.urdf_twin.fold_helper_parts`). Names
  come from ``semantics.txt`` (``<label>_<k>``, k counting per label), the base stays ``base``.
* Frame and units: the URDF base frame (z up: SAPIEN/PartNet's root fixed joint turns the y-up
  annotation frame with rpy (π/2, 0, -π/2)); PartNet's unitless scale (``units: "scene"``) unless a
  metric scale is given (``units: "m"``).
* Geometry: watertight copies for evaluation (``twin/parts/*.ply``), original textured meshes as
  visuals (``twin/visual/*.obj``).
* States: the RS-Art protocol; continuous joints (knobs) use a quarter turn, recorded in meta.json.
* ``mobility_v2.json`` check: its hinge limits are degrees in the annotation frame, may exceed ±360°
  and may have lower > upper; PartNet's URDF then flips the axis and negates the limits, and shifts
  them by whole turns. Each joint records the sign (+1/-1) and the turn shift that map the JSON onto
  the URDF (``joint.extra["mobility_v2"]``).
"""
from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..checks import is_safe_id
from ..errors import RsartError
from ..format import DatasetIndex, ObjectMeta, read_index, write_index
from ..io import read_json
from ..kinematics import Twin, TwinPart
from ..states import QUARTER_TURN
from .urdf_twin import (WatertightConfig, check_geometry, conversion_notes, fold_helper_parts, reindexed,
                        scale_twin, with_watertight_meshes)

URDF_NAME = "mobility.urdf"
MAX_JSON_BYTES = 20 * 1024 * 1024
#: rotation taking the "rotated to z-up" frame of PARIS/DTArt/ArtGS ground truth (their ``R_coord``, +90° about x
#: applied to the y-up annotation frame) to rsart's world frame: a further -90° about z (the URDF root joint's
#: rpy (π/2, 0, -π/2) = Rz(-π/2)·Rx(π/2)). ``p_rsart = PARIS_ZUP_TO_WORLD @ p_paris``; no translation.
PARIS_ZUP_TO_WORLD = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
WORLD_FRAME_NOTE = ("URDF base frame of mobility.urdf at rest (all joints 0), z up: PartNet-Mobility's root "
                    "fixed joint (rpy = pi/2, 0, -pi/2) turns the y-up annotation frame of mobility_v2.json "
                    "into it, as SAPIEN loads the object; PARIS/DTArt 'rotated to z-up' ground truth = this frame "
                    "turned +90 degrees about z (p_paris = Rz(+90) p_rsart)")


@dataclass
class PartnetInfo:
    """What the side files of a PartNet-Mobility folder say (``semantics``: link -> (joint kind, label))."""

    folder_id: str
    category: str
    anno_id: str | None
    model_id: str | None
    version: str | None
    semantics: dict[str, tuple[str, str]] = field(default_factory=dict)
    mobility: dict[int, dict[str, Any]] = field(default_factory=dict)


# ----------------------------------------------------------------------------- side files
def _read_small_json(path: Path) -> Any:
    try:
        size = path.stat().st_size
    except OSError as e:
        raise RsartError(f"{path}: cannot read ({e.strerror})") from None
    if size > MAX_JSON_BYTES:
        raise RsartError(f"{path}: {size} bytes exceeds the limit of {MAX_JSON_BYTES}")
    return read_json(path)


def read_semantics(path: Path) -> dict[str, tuple[str, str]]:
    """``semantics.txt``: lines ``<link> <joint kind> <label>`` -> {link: (kind, label)}; {} if absent."""
    if not path.is_file():
        return {}
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise RsartError(f"{path}: cannot read ({e})") from None
    out = {}
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        f = line.split()
        if len(f) != 3:
            raise RsartError(f"{path}: line {n}: expected '<link> <joint kind> <label>', got {line.strip()[:60]!r}")
        out[f[0]] = (f[1], f[2])
    return out


def read_mobility_v2(path: Path) -> dict[int, dict[str, Any]]:
    """``mobility_v2.json`` -> {id: entry}; {} if absent. Raises RsartError naming the file on bad structure."""
    if not path.is_file():
        return {}
    d = _read_small_json(path)
    if not isinstance(d, list):
        raise RsartError(f"{path}: expected a list of joints, got {type(d).__name__}")
    out = {}
    for i, e in enumerate(d):
        if not isinstance(e, dict) or not isinstance(e.get("id"), int) or isinstance(e.get("id"), bool):
            raise RsartError(f"{path}: [{i}]: expected an object with an integer 'id'")
        jd = e.get("jointData")
        if jd and not isinstance(jd, dict):
            raise RsartError(f"{path}: [{i}].jointData: expected an object")
        out[e["id"]] = e
    return out


def read_partnet_info(obj_dir: Path) -> PartnetInfo:
    """Read ``meta.json`` (category = ``model_cat``, ``anno_id``), ``semantics.txt`` and ``mobility_v2.json``."""
    meta_path = obj_dir / "meta.json"
    if not meta_path.is_file():
        raise RsartError(f"{meta_path}: file not found (not a PartNet-Mobility object folder?)")
    m = _read_small_json(meta_path)
    if not isinstance(m, dict):
        raise RsartError(f"{meta_path}: expected a JSON object")
    cat = m.get("model_cat")
    if not isinstance(cat, str) or not cat.strip():
        raise RsartError(f"{meta_path}: model_cat: expected a non-empty string, got {cat!r}")

    def opt(k: str) -> str | None:
        v = m.get(k)
        return None if v is None else str(v)

    return PartnetInfo(obj_dir.name, cat.strip(), opt("anno_id"), opt("model_id"), opt("version"),
                       read_semantics(obj_dir / "semantics.txt"), read_mobility_v2(obj_dir / "mobility_v2.json"))


# ----------------------------------------------------------------------------- twin
def _link_transforms(urdf_path: Path) -> dict[str, np.ndarray]:
    """Rest transforms (base frame) of every link of a URDF that read_urdf accepted (a tree).

    The bytes are checked again (no DTD/entities) before parsing: the file may have changed since.
    """
    import io

    import yourdfpy

    from ..urdf import check_xml

    data = urdf_path.read_bytes()
    check_xml(data, str(urdf_path))
    try:
        robot = yourdfpy.URDF.load(io.BytesIO(data), load_meshes=False, build_scene_graph=False,
                                   build_collision_scene_graph=False, load_collision_meshes=False).robot
    except Exception as e:
        raise RsartError(f"{urdf_path}: not a valid URDF ({type(e).__name__}: {e})") from None
    children = {j.child for j in robot.joints}
    T = {l.name: np.eye(4) for l in robot.links if l.name not in children}
    pending = list(robot.joints)
    while pending:
        rest = [j for j in pending if j.parent not in T]
        for j in pending:
            if j.parent in T:
                T[j.child] = T[j.parent] @ np.asarray(j.origin, dtype=float)
        if len(rest) == len(pending):
            break
        pending = rest
    return T


def _link_id(link: str) -> int | None:
    m = re.fullmatch(r"link_(\d+)", link)
    return int(m.group(1)) if m else None


def _main_link(part: TwinPart) -> str:
    links = [l for l in part.extra.get("links", []) if l != "base"]
    return links[0] if links else (part.extra.get("links") or [part.name])[0]


def name_parts(twin: Twin, semantics: dict[str, tuple[str, str]]) -> Twin:
    """Parts renamed ``<label>_<k>`` from semantics.txt (base stays ``base``); joints renamed
    ``<part>_hinge`` / ``<part>_slide``; original names kept in ``extra``."""
    counts: dict[str, int] = {}
    parts = []
    for p in twin.parts:
        link = _main_link(p)
        kind, label = semantics.get(link, (None, None))
        extra = dict(p.extra)
        if label:
            extra["semantic"] = label
        if p.index == 0:
            name = "base"
        else:
            stem = re.sub(r"[^A-Za-z0-9_]", "_", label or link).strip("_")[:60] or "part"
            name = f"{stem}_{counts.get(stem, 0)}"
            counts[stem] = counts.get(stem, 0) + 1
        parts.append(TwinPart(p.index, name, p.mesh, p.visuals, extra))
    joints = []
    for j in twin.joints:
        pname = parts[j.child].name
        joints.append(replace(j, name=f"{pname}_{'hinge' if j.type == 'revolute' else 'slide'}",
                              extra={"urdf_joint": j.name, **j.extra}))
    return reindexed(twin.name, parts, joints)


def _finite(v: Any, n: int) -> bool:
    """True for a list of ``n`` finite numbers (JSON may hold 1e999 = inf, or anything else)."""
    return (isinstance(v, list) and len(v) == n and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and abs(x) < 1e9 for x in v))


def mobility_check(joint, mob: dict[str, Any], R_root: np.ndarray) -> dict[str, Any]:
    """How ``mobility_v2.json``'s entry maps onto the URDF joint (world frame, see module docstring).

    Returns ``{joint, direction, limit, sign, turns, agrees}``: ``sign`` = ±1 between the JSON direction
    (turned into the world frame) and the URDF axis; URDF limits = sign·JSON limits + turns·2π (hinge).
    """
    jd = mob.get("jointData") or {}
    ax = (jd.get("axis") or {}).get("direction") if isinstance(jd.get("axis"), dict) else None
    lim = jd.get("limit") if isinstance(jd.get("limit"), dict) else {}
    a, b = lim.get("a"), lim.get("b")
    rec: dict[str, Any] = {"joint": str(mob.get("joint"))[:40], "direction": ax if _finite(ax, 3) else None,
                           "limit": [a, b] if _finite([a, b], 2) else None, "noLimit": lim.get("noLimit") is True}
    if rec["direction"] is None or np.linalg.norm(ax) < 1e-12:
        rec["agrees"] = False
        return rec
    d = R_root @ np.asarray(ax, dtype=float)
    d = d / np.linalg.norm(d)
    cosang = float(np.dot(d, joint.axis))
    sign = 1 if cosang >= 0 else -1
    rec["sign"] = sign
    ok = abs(abs(cosang) - 1.0) < 1e-6
    if joint.limits is not None:
        if rec["limit"] is None:
            ok = False
        else:
            conv = math.radians if joint.type == "revolute" else float
            lo, hi = sign * conv(a), sign * conv(b)
            if joint.type == "revolute":
                turns = round((joint.limits[0] - lo) / (2 * math.pi))
                rec["turns"] = turns
                lo, hi = lo + 2 * math.pi * turns, hi + 2 * math.pi * turns
            ok = ok and abs(lo - joint.limits[0]) < 1e-6 and abs(hi - joint.limits[1]) < 1e-6
    rec["agrees"] = bool(ok)
    return rec


def read_partnet(obj_dir: str | os.PathLike) -> tuple[Twin, PartnetInfo, list[str], str]:
    """Read a PartNet-Mobility folder: (twin at scene scale without watertight copies, info, notes, root link)."""
    from ..urdf import read_urdf

    obj_dir = Path(obj_dir)
    if not obj_dir.is_dir():
        raise RsartError(f"{obj_dir}: not a folder")
    urdf_path = obj_dir / URDF_NAME
    if not urdf_path.is_file():
        raise RsartError(f"{urdf_path}: file not found (not a PartNet-Mobility object folder?)")
    info = read_partnet_info(obj_dir)
    twin = read_urdf(urdf_path)
    twin, notes = fold_helper_parts(twin, str(urdf_path))
    check_geometry(twin, str(urdf_path))
    twin = name_parts(twin, info.semantics)
    T = _link_transforms(urdf_path)
    root_link = _main_link(twin.parts[0])
    R_root = T.get(root_link, np.eye(4))[:3, :3]
    joints = []
    for j in twin.joints:
        extra = dict(j.extra)
        lid = _link_id(_main_link(twin.parts[j.child]))
        if lid is not None and lid in info.mobility:
            rec = mobility_check(j, info.mobility[lid], R_root)
            extra["mobility_v2"] = rec
            if not rec["agrees"]:
                notes.append(f"joint {j.name}: mobility_v2.json disagrees with mobility.urdf beyond the sign/turn "
                             "rule; the URDF is used")
        joints.append(replace(j, extra=extra))
    return Twin(twin.name, twin.parts, joints), info, notes, root_link


def convert_partnet(obj_dir: str | os.PathLike, out: str | os.PathLike, *, object_id: str | None = None,
                    metric_scale: float | None = None, overwrite: bool = False,
                    watertight: WatertightConfig = WatertightConfig(),
                    unlimited_range: tuple[float, float] = QUARTER_TURN,
                    log: Callable[[str], None] | None = None,
                    progress: Callable[[int, int, str], None] | None = None) -> ObjectMeta:
    """Convert one PartNet-Mobility object folder into an RS-Art object folder ``out`` (atomically).

    ``object_id`` defaults to ``pm-<folder id>``. ``metric_scale``: metres per PartNet unit (then
    ``units`` = "m"); by default the original scene units are kept (``units`` = "scene").
    """
    from ..states import protocol_states
    from ..twin_io import write_object

    obj_dir = Path(obj_dir)
    twin, info, notes, root_link = read_partnet(obj_dir)
    oid = object_id or f"pm-{info.folder_id}"
    if not is_safe_id(oid):
        raise RsartError(f"{obj_dir}: object id {oid!r} is not a safe id; pass one explicitly")
    units = "scene"
    extra: dict[str, Any] = {"world_frame": WORLD_FRAME_NOTE, "root_link": root_link}
    if metric_scale is not None:
        twin = scale_twin(twin, metric_scale)
        units = "m"
        extra["scale_to_metres"] = float(metric_scale)
    twin = with_watertight_meshes(twin, watertight, log, progress)
    extra.update(conversion_notes(twin, notes, unlimited_range, source=str(obj_dir)))
    states, ev = protocol_states(twin.joints, unlimited_range=unlimited_range)
    source = {"kind": "partnet-mobility", "id": info.folder_id, "anno_id": info.anno_id,
              "model_id": info.model_id, "version": info.version}
    return write_object(twin, out, object_id=oid, category=info.category,
                        source={k: v for k, v in source.items() if v is not None}, units=units,
                        states=states, eval_states=ev, extra_meta=extra, overwrite=overwrite)


# ----------------------------------------------------------------------------- splits and batches
def split_names() -> list[str]:
    """Names of the split files shipped with rsart (``rsart/sources/splits/*.json``)."""
    return sorted(p.name[:-5] for p in resources.files(__package__).joinpath("splits").iterdir()
                  if p.name.endswith(".json"))


def split_ids(name: str) -> list[str]:
    """PartNet-Mobility ids of the shipped split ``name`` (e.g. ``pd2gs-paper``)."""
    if name not in split_names():
        raise RsartError(f"unknown split {name!r} (known: {split_names()})")
    d = json.loads(resources.files(__package__).joinpath("splits", f"{name}.json").read_text(encoding="utf-8"))
    return [str(o["id"]) for o in d["objects"]]


@dataclass
class BatchReport:
    """Outcome of a batch conversion: converted object ids, ids missing from the root, failures (id -> message)."""

    converted: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)


def convert_partnet_root(root: str | os.PathLike, out_root: str | os.PathLike, ids: list[str], *,
                         split: str | None = None, metric_scale: float | None = None, overwrite: bool = False,
                         watertight: WatertightConfig = WatertightConfig(),
                         log: Callable[[str], None] | None = None,
                         progress_for: Callable[[str], Any] | None = None,
                         on_done: Callable[[str, str, Any], None] | None = None) -> BatchReport:
    """Convert ``root/<id>`` for each id into ``out_root/pm-<id>``; missing ids and failures are reported,
    not fatal. An existing ``pm-<id>`` object folder is kept (``skipped``) unless ``overwrite``, so an
    interrupted batch can be re-run. ``out_root/index.json`` lists the objects (merged with an existing
    index) and ``split``.

    ``progress_for(id)`` may return a per-object progress callback (see :func:`convert_partnet`; its
    ``close()`` is called when the object is done); ``on_done(id, status, detail)`` is called per id with
    status "converted" (detail: the ObjectMeta), "kept", "missing" or "failed" (detail: the message)."""
    root, out_root = Path(root), Path(out_root)
    if not root.is_dir():
        raise RsartError(f"{root}: not a folder")
    rep = BatchReport()
    def done(i: str, status: str, detail: Any = None) -> None:
        if on_done:
            on_done(i, status, detail)

    for i in ids:
        if not is_safe_id(i) or not (root / i).is_dir():
            rep.missing.append(i)
            done(i, "missing", f"not in {root}")
            continue
        if not overwrite and (out_root / f"pm-{i}" / "meta.json").is_file():
            rep.skipped.append(f"pm-{i}")
            if log:
                log(f"{i}: {out_root / f'pm-{i}'} exists, kept (pass overwrite to redo it)")
            done(i, "kept")
            continue
        bar = progress_for(i) if progress_for else None
        try:
            meta = convert_partnet(root / i, out_root / f"pm-{i}", metric_scale=metric_scale, overwrite=overwrite,
                                   watertight=watertight, log=log, progress=bar)
        except RsartError as e:
            rep.failed[i] = str(e)
            if log:
                log(f"{i}: FAILED: {e}")
            done(i, "failed", str(e))
        else:
            rep.converted.append(meta.object_id)
            if log:
                log(f"{i}: converted to {out_root / meta.object_id}")
            done(i, "converted", meta)
        finally:
            if bar is not None and hasattr(bar, "close"):
                bar.close()
    if rep.converted or rep.skipped:
        _update_index(out_root, rep.converted + rep.skipped, split)
    return rep


def _update_index(out_root: Path, objects: list[str], split: str | None) -> None:
    idx_path = out_root / "index.json"
    if idx_path.is_file():
        idx = read_index(idx_path)
    else:
        idx = DatasetIndex("partnet-mobility", "1", [], {})
    for o in objects:
        if o not in idx.objects:
            idx.objects.append(o)
    if split:
        idx.splits[split] = list(dict.fromkeys(idx.splits.get(split, []) + objects))
    write_index(idx, idx_path)
