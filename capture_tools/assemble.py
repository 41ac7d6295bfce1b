"""Assemble an RS-Art object folder from a raw capture, its capture log and the reverse-modelled twin.

``states.yaml`` (the capture log; paths relative to its folder)::

    object_id: drawer-0001            # optional (default: the twin's name)
    category: drawer                  # optional
    units: m
    eval_states: {start: m0, end: m3} # optional (default: first and last multi state)
    states:
      - {id: m0, kind: multi, values: {slide: 0.0}, recording: m0}          # frame folder / video folder
      - {id: s1max, kind: single, joint: slide, extreme: max, values: {slide: 0.3}, recording: s1max.bag}

Output (docs/format.md): meta.json (the log's states, ``source.kind = "rs-art"``), twin/ (written by
:func:`rsart.twin_io.write_object`), ``states/<id>/{cameras.json, rgb/, depth/, mask/}`` with the
selected frames, object-frame poses and part masks, and ``capture.json`` with every step's figures.
The folder is built in a temporary sibling and renamed into place when complete.
"""
from __future__ import annotations

import math
from pathlib import Path

import yaml

from rsart.errors import RsartError
from rsart.format import CamerasFile, State, ViewRecord, write_cameras
from rsart.io import atomic_dir, is_empty_dir, write_depth_png, write_json, write_mask_png, write_png_rgb
from rsart.kinematics import Twin

from .joint import process_joint
from .pipeline import CaptureSettings, process_state, reconstruct_state
from .recording import open_recording


def load_twin(path: str | Path) -> Twin:
    """A twin from a URDF, a USD file or an rsart object folder."""
    p = Path(path)
    if p.is_dir() and (p / "meta.json").is_file():
        from rsart.twin_io import read_twin
        return read_twin(p)
    suffix = p.suffix.lower()
    if p.is_file() and suffix == ".urdf":
        from rsart.urdf import read_urdf
        return read_urdf(p)
    if p.is_file() and suffix in (".usd", ".usda", ".usdc"):
        from rsart.usd import read_usd
        return read_usd(p)
    raise RsartError(f"{p}: expected a twin as .urdf, .usd/.usda/.usdc or an object folder with meta.json")


def read_capture_log(path: str | Path, twin: Twin) -> tuple[dict, list[State], list[str]]:
    """(log dict, states, recording paths) from ``states.yaml``, checked against the twin's joints."""
    path = Path(path)
    try:
        d = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise RsartError(f"{path}: capture log not found") from None
    except yaml.YAMLError as e:
        raise RsartError(f"{path}: invalid YAML ({e})") from None
    if not isinstance(d, dict) or not isinstance(d.get("states"), list) or not d["states"]:
        raise RsartError(f"{path}: expected a mapping with a non-empty 'states' list")
    names = {j.name for j in twin.joints}
    states, recs, seen = [], [], set()
    for i, s in enumerate(d["states"]):
        where = f"{path}: states[{i}]"
        if not isinstance(s, dict):
            raise RsartError(f"{where}: expected a mapping")
        for key in ("id", "kind", "values", "recording"):
            if key not in s:
                raise RsartError(f"{where}: missing '{key}'")
        if s["id"] in seen:
            raise RsartError(f"{where}.id: duplicate state id {s['id']!r}")
        seen.add(s["id"])
        if s["kind"] not in ("multi", "single"):
            raise RsartError(f"{where}.kind: {s['kind']!r} is not 'multi' or 'single'")
        vals = s["values"]
        if not isinstance(vals, dict) or set(vals) != names:
            raise RsartError(f"{where}.values: must give every twin joint exactly ({sorted(names)}), "
                             f"got {sorted(vals) if isinstance(vals, dict) else vals!r}")
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in vals.values()):
            raise RsartError(f"{where}.values: joint values must be finite numbers (radians / metres)")
        joint, extreme = (s.get("joint"), s.get("extreme")) if s["kind"] == "single" else (None, None)
        if s["kind"] == "single" and (joint not in names or extreme not in ("min", "max")):
            raise RsartError(f"{where}: a single state needs 'joint' (one of {sorted(names)}) and 'extreme' (min|max)")
        rel = str(s["recording"])
        rp = (path.parent / rel).resolve()
        if not rp.is_relative_to(path.parent.resolve()):
            raise RsartError(f"{where}.recording: {rel!r} points outside the raw capture folder")
        states.append(State(str(s["id"]), s["kind"], {k: float(v) for k, v in vals.items()}, joint, extreme))
        recs.append(rp)
    return d, states, [str(r) for r in recs]


def assemble(raw_dir: str | Path, twin_path: str | Path, states_yaml: str | Path | None, out: str | Path,
             settings: CaptureSettings = CaptureSettings(), overwrite: bool = False,
             progress=print) -> dict:
    """Build the object folder ``out`` (see module docstring); returns the capture report (also capture.json)."""
    from rsart.twin_io import write_object

    raw_dir = Path(raw_dir)
    if not raw_dir.is_dir():
        raise RsartError(f"{raw_dir}: raw capture folder not found")
    twin = load_twin(twin_path)
    log, states, recs = read_capture_log(Path(states_yaml) if states_yaml else raw_dir / "states.yaml", twin)
    object_id = str(log.get("object_id") or twin.name)
    multi = [s.id for s in states if s.kind == "multi"] or [s.id for s in states]
    eval_states = log.get("eval_states") or {"start": multi[0], "end": multi[-1]}
    known = {s.id for s in states}
    if not isinstance(eval_states, dict) or set(eval_states) != {"start", "end"} or not set(eval_states.values()) <= known:
        raise RsartError(f"capture log eval_states {eval_states!r}: needs 'start' and 'end' naming logged states "
                         f"({sorted(known)})")
    out = Path(out)
    if out.exists() and not overwrite and not is_empty_dir(out):
        raise RsartError(f"{out}: already exists and is not empty (pass --overwrite to replace it)")
    report: dict = {"format": "rsart-capture/1", "raw": str(raw_dir), "settings": {"n_views": settings.n_views},
                    "states": {}}
    with atomic_dir(out, overwrite=overwrite) as tmp:
        write_object(twin, tmp, object_id=object_id, category=str(log.get("category", "unknown")),
                     source={"kind": "rs-art", "id": object_id, "capture": "capture_tools"},
                     units=str(log.get("units", "m")), states=states, eval_states=dict(eval_states), overwrite=True)
        for st, rec, res in _results(states, recs, twin, settings, report, progress):
            sdir = tmp / "states" / st.id
            views = []
            for i, f in enumerate(res.frames):
                vid = f"{i:04d}"
                key = f"{f.name}.png" if f"{f.name}.png" in res.c2w else f.name
                write_png_rgb(sdir / "rgb" / f"{vid}.png", f.rgb)
                write_depth_png(sdir / "depth" / f"{vid}.png", f.depth, rec.depth_scale)
                write_mask_png(sdir / "mask" / f"{vid}.png", res.masks[key])
                views.append(ViewRecord(vid, res.c2w[key], "train", {"frame": f.name, "timestamp": f.timestamp}))
            write_cameras(CamerasFile(rec.intrinsics, rec.depth_scale, views,
                                      {"state": st.id, "poses": "capture_tools (SfM + depth + twin registration)"}),
                          sdir / "cameras.json")
            res.report["T_world_to_capture"] = res.registration.T.tolist()
            report["states"][st.id] = res.report
            r = res.report["registration"]
            progress(f"[{st.id}] {len(views)} views, twin residual {1000 * r['icp_rmse']:.2f} mm "
                     f"(fitness {r['icp_fitness']:.3f})")
        write_json(tmp / "capture.json", report)
    return report


def _results(states: list[State], recs: list[str], twin: Twin, settings: CaptureSettings, report: dict, progress):
    """(state, recording, StateResult) per state: one state at a time (``per-state``), or all reconstructed
    first and then solved together (``joint``, capture_tools.joint; figures in ``report["joint"]``)."""
    if settings.sfm not in ("per-state", "joint"):
        raise RsartError(f"SfM mode {settings.sfm!r} is not 'per-state' or 'joint'")
    report["settings"]["sfm"] = settings.sfm
    if settings.sfm == "per-state":
        for st, rp in zip(states, recs):
            progress(f"[{st.id}] {rp}")
            rec = open_recording(rp)
            yield st, rec, process_state(rec, twin, st.values, settings)
        return
    opened, recons = [], []
    for st, rp in zip(states, recs):
        progress(f"[{st.id}] {rp}: reconstructing")
        rec = open_recording(rp)
        opened.append(rec)
        recons.append(reconstruct_state(rec, settings))
    intr = opened[0].intrinsics
    for st, rec in zip(states, opened):
        if rec.intrinsics.to_dict() != intr.to_dict():
            raise RsartError(f"{rec.source}: joint SfM needs one camera; state {st.id}'s intrinsics differ "
                             f"from {states[0].id}'s (use --sfm per-state)")
    progress(f"joint SfM over {sum(len(r.frames) for r in recons)} frames of {len(states)} states")
    results, report["joint"] = process_joint(recons, [s.id for s in states], intr, twin, [s.values for s in states],
                                             settings)
    yield from zip(states, opened, results)
