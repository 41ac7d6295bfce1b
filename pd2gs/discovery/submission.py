"""Write PD²GS results as an ``rsart-submission/1`` folder (DESIGN.md §6.2, docs/evaluation.md).

Layout: ``<out>/submission.json`` and ``<out>/<object_id>/<state_id>/<part>.ply`` (+ ``whole.ply``); paths in
the JSON are relative to ``<out>``. Part names: ``static`` for label 0, ``p1``, ``p2``, ... for the movable
parts. Joints: axis/origin in the world frame at the ``start`` state, values per state id. An object whose
result is ``None`` or an exception is written as ``null`` and its reason goes to ``failures.json`` (and the
log); writing never raises because of one object.
"""
from __future__ import annotations

import logging
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import trimesh

from rsart.errors import RsartError
from rsart.io import atomic_dir, atomic_write_bytes, write_json

from pd2gs.kinematics import JointFit

FORMAT = "rsart-submission/1"
log = logging.getLogger(__name__)


@dataclass
class PartResult:
    """One discovered part: ``label`` (0 = static), ``meshes`` state id -> world-frame mesh, ``joint``."""

    name: str
    label: int
    meshes: dict[str, trimesh.Trimesh] = field(default_factory=dict)
    joint: JointFit | None = None


@dataclass
class ObjectResult:
    """PD²GS output for one object: parts (static first), whole-object meshes per state, diagnostics."""

    object_id: str
    parts: list[PartResult]
    whole: dict[str, trimesh.Trimesh] = field(default_factory=dict)
    diagnostics: dict[str, Any] = field(default_factory=dict)
    field: Any = None  # the refined, labelled StateField (for pictures); not written


class ObjectFailure(RsartError):
    """A failed object with its reason (what ``discover`` returns through the pipeline's safe wrapper)."""


def canonical_order(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The same mesh with vertices sorted by (x, y, z) and faces sorted, each face's smallest index first
    (winding kept). open3d's TSDF hash map emits the same triangles in a run-dependent order; written in
    this order, the same geometry is the same bytes. (V, 3), (F, 3) -> (V, 3), (F, 3)."""
    v = np.asarray(vertices)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    order = np.lexsort((v[:, 2], v[:, 1], v[:, 0])) if len(v) else np.zeros(0, np.int64)
    rank = np.empty(len(v), np.int64)
    rank[order] = np.arange(len(v))
    if len(f):
        f = rank[f]
        f = np.take_along_axis(f, (np.arange(3)[None, :] + np.argmin(f, axis=1)[:, None]) % 3, axis=1)
        f = f[np.lexsort((f[:, 2], f[:, 1], f[:, 0]))]
    return v[order], f


def _ply(mesh: trimesh.Trimesh) -> bytes:
    v, f = canonical_order(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    geom = trimesh.Trimesh(v, f, process=False)
    return trimesh.exchange.ply.export_ply(geom, encoding="binary")


def object_entry(res: ObjectResult, root: Path) -> dict:
    """Write one object's meshes under ``root`` and return its JSON entry (paths relative to root).

    Empty meshes are skipped (the validator rejects empty files); a movable part keeps its joint.
    """
    parts: dict[str, dict] = {}
    for p in res.parts:
        entry: dict[str, Any] = {"meshes": {}}
        for sid, m in p.meshes.items():
            if m is None or len(m.faces) == 0:
                continue
            rel = f"{res.object_id}/{sid}/{p.name}.ply"
            atomic_write_bytes(root / rel, _ply(m))
            entry["meshes"][sid] = rel
        if p.joint is not None:
            entry["joint"] = p.joint.to_submission()
        parts[p.name] = entry
    out: dict[str, Any] = {"parts": parts}
    whole = {}
    for sid, m in res.whole.items():
        if m is None or len(m.faces) == 0:
            continue
        rel = f"{res.object_id}/{sid}/whole.ply"
        atomic_write_bytes(root / rel, _ply(m))
        whole[sid] = rel
    if whole:
        out["whole"] = whole
    return out


def write_submission(results: Mapping[str, ObjectResult | BaseException | None], out_dir: str | os.PathLike,
                     method_block: dict, dataset_block: dict | None = None, overwrite: bool = False) -> Path:
    """Write every object's result (None / exception = failure -> null) to ``out_dir``; -> submission.json.

    ``method_block``: the submission's ``method`` object (needs ``name``); ``dataset_block``: ``{"name",
    "version"}`` of the evaluated dataset. The folder is built atomically.
    """
    if not isinstance(method_block, dict) or not method_block.get("name"):
        raise ValueError("method_block needs a non-empty 'name'")
    out = Path(out_dir)
    entries: dict[str, Any] = {}
    failures: dict[str, str] = {}
    with atomic_dir(out, overwrite=overwrite) as tmp:
        for oid, res in results.items():
            if isinstance(res, ObjectResult):
                try:
                    entries[oid] = object_entry(res, tmp)
                    continue
                except Exception as e:  # one object's bad output must not sink the others
                    reason = f"writing failed: {type(e).__name__}: {e}"
            elif res is None:
                reason = "no result"
            else:
                reason = f"{type(res).__name__}: {res}"
            log.warning("%s: failed (%s); written as null", oid, reason)
            entries[oid] = None
            failures[oid] = reason
        _write_doc(tmp, entries, failures, method_block, dataset_block)
    return out / "submission.json"


def _write_doc(tmp: Path, entries: dict, failures: dict, method_block: dict, dataset_block: dict | None) -> None:
    doc = {"format": FORMAT, "method": dict(method_block), "dataset": dict(dataset_block or {}), "results": entries}
    write_json(tmp / "submission.json", doc)
    if failures:
        write_json(tmp / "failures.json", failures)


def write_submission_entries(entries: Mapping[str, dict | None], failures: Mapping[str, str],
                             mesh_dirs: Mapping[str, Path], out_dir: str | os.PathLike, method_block: dict,
                             dataset_block: dict | None = None) -> Path:
    """Write a submission from entries already written by :func:`object_entry` (``pd2gs.runner``'s per-object
    results): entry paths are relative to ``mesh_dirs[object_id]``, whose ``<object_id>/`` folder is copied.
    ``None`` entries are failures (reason in ``failures``). Replaces ``out_dir`` atomically; -> submission.json.
    """
    if not isinstance(method_block, dict) or not method_block.get("name"):
        raise ValueError("method_block needs a non-empty 'name'")
    out = Path(out_dir)
    with atomic_dir(out, overwrite=True) as tmp:
        for oid, entry in entries.items():
            if entry is not None and (Path(mesh_dirs[oid]) / oid).is_dir():
                shutil.copytree(Path(mesh_dirs[oid]) / oid, tmp / oid)
        _write_doc(tmp, dict(entries), {k: failures[k] for k in entries if k in failures}, method_block,
                   dataset_block)
    return out / "submission.json"
