"""Add (or replace) one object's entry of an ``rsart-submission/1`` file (DESIGN.md §6.2).

Meshes go to ``<submission stem>_meshes/<object_id>/<state>/<part>.ply`` beside the submission file
(that object's folder is rebuilt atomically), then the JSON is rewritten atomically with the entry.
The adapter's notes (how a motion was estimated, which run files were read) go to
``<submission stem>.import-log.json``, since the submission format has no place for them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from rsart.errors import RsartError
from rsart.io import atomic_dir, atomic_write_bytes, read_json, write_json

FORMAT = "rsart-submission/1"
STATIC = "static"


@dataclass
class PartOut:
    """A predicted part: ``meshes`` state id -> mesh (rsart world); ``joint`` None for the static part,
    else ``{"type", "axis", "origin", "values": {state id: value}}`` (world frame at the start state)."""

    name: str
    meshes: dict[str, trimesh.Trimesh] = field(default_factory=dict)
    joint: dict[str, Any] | None = None


def _ply(mesh: trimesh.Trimesh) -> bytes:
    return trimesh.exchange.ply.export_ply(trimesh.Trimesh(mesh.vertices, mesh.faces, process=False), encoding="binary")


def _joint_json(j: dict[str, Any]) -> dict[str, Any]:
    return {"type": j["type"], "axis": [float(x) for x in np.asarray(j["axis"]).reshape(3)],
            "origin": [float(x) for x in np.asarray(j["origin"]).reshape(3)],
            "values": {k: float(v) for k, v in j["values"].items()}}


def _load(submission: Path, method: dict[str, Any], dataset: dict[str, Any] | None) -> dict[str, Any]:
    if not submission.exists():
        return {"format": FORMAT, "method": method, "dataset": dict(dataset or {}), "results": {}}
    d = read_json(submission)
    if not isinstance(d, dict) or d.get("format") != FORMAT or not isinstance(d.get("results"), dict):
        raise RsartError(f"{submission}: not an {FORMAT} file (refusing to overwrite it)")
    old = d.get("method", {}).get("name") if isinstance(d.get("method"), dict) else None
    if old != method["name"]:
        raise RsartError(f"{submission}: holds results of method {old!r}, not {method['name']!r}; "
                         f"use one submission file per method")
    if dataset:
        d.setdefault("dataset", {}).update({k: v for k, v in dataset.items() if k not in d["dataset"]})
    return d


def write_entry(submission: Path, object_id: str, parts: list[PartOut], method: dict[str, Any],
                dataset: dict[str, Any] | None = None, whole: dict[str, trimesh.Trimesh] | None = None,
                notes: list[str] | None = None) -> Path:
    """Write ``object_id``'s entry (replacing any earlier one); returns the submission path."""
    submission = Path(submission)
    if submission.suffix != ".json":
        raise RsartError(f"{submission}: the submission file must end in .json")
    if not parts or parts[0].name != STATIC or parts[0].joint is not None:
        raise RsartError(f"{object_id}: the first part must be the static part named {STATIC!r}")
    doc = _load(submission, method, dataset)
    mesh_root = f"{submission.stem}_meshes"
    entry: dict[str, Any] = {"parts": {}}
    with atomic_dir(submission.parent / mesh_root / object_id, overwrite=True) as tmp:
        for p in parts:
            rec: dict[str, Any] = {"meshes": {}}
            for sid, m in p.meshes.items():
                if m is None or len(m.faces) == 0:
                    continue
                rel = f"{sid}/{p.name}.ply"
                atomic_write_bytes(tmp / rel, _ply(m))
                rec["meshes"][sid] = f"{mesh_root}/{object_id}/{rel}"
            if p.joint is not None:
                rec["joint"] = _joint_json(p.joint)
            entry["parts"][p.name] = rec
        if whole:
            entry["whole"] = {}
            for sid, m in whole.items():
                rel = f"{sid}/whole.ply"
                atomic_write_bytes(tmp / rel, _ply(m))
                entry["whole"][sid] = f"{mesh_root}/{object_id}/{rel}"
    doc["results"][object_id] = entry
    write_json(submission, doc)
    _log(submission, object_id, notes or [])
    return submission


def write_failure(submission: Path, object_id: str, method: dict[str, Any], reason: str,
                  dataset: dict[str, Any] | None = None) -> Path:
    """Record that the method failed on ``object_id`` (``null`` entry: scored as a failure)."""
    submission = Path(submission)
    doc = _load(submission, method, dataset)
    doc["results"][object_id] = None
    write_json(submission, doc)
    _log(submission, object_id, [f"failed: {reason}"])
    return submission


def _log(submission: Path, object_id: str, notes: list[str]) -> None:
    path = submission.with_name(f"{submission.stem}.import-log.json")
    log = read_json(path) if path.exists() else {}
    if not isinstance(log, dict):
        log = {}
    log[object_id] = notes
    write_json(path, log)
