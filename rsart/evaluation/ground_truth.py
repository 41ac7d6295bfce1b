"""The ground truth a submission is scored against: object folders of an RS-Art dataset.

Only ``meta.json`` (parts, joints, states) and the twin's part meshes are needed; rendered images are
read only when a submission includes renders or part masks.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from ..errors import RsartError
from ..format import ObjectMeta, read_index, read_meta
from ..io import resolve_inside


@dataclass
class GroundTruth:
    """Objects to score: ``objects`` maps object id -> (object folder, meta), in dataset order.

    ``name``/``version`` come from ``index.json`` (None for a single object folder); ``split`` is the
    split scored (None = every object).
    """

    root: Path
    name: str | None
    version: str | None
    split: str | None
    objects: dict[str, tuple[Path, ObjectMeta]]

    def meta(self, object_id: str) -> ObjectMeta:
        return self.objects[object_id][1]

    def folder(self, object_id: str) -> Path:
        return self.objects[object_id][0]


def resolve_states(meta: ObjectMeta, spec: str) -> list[str]:
    """State ids named by ``spec``: "all", or a comma list of ids and the aliases ``start``/``end``."""
    ids = [s.id for s in meta.states]
    if spec.strip() == "all":
        return ids
    out: list[str] = []
    for tok in (t.strip() for t in spec.split(",")):
        sid = meta.eval_states.get(tok, tok) if tok in ("start", "end") else tok
        if sid not in ids:
            raise RsartError(f"{meta.object_id}: --states names {tok!r}, which is not a state (states: {ids})")
        if sid not in out:
            out.append(sid)
    return out


def load_ground_truth(data: str | os.PathLike, split: str | None = None) -> GroundTruth:
    """Read a dataset root (``index.json``) or a single object folder (``meta.json``).

    Raises RsartError (or ValidationError) naming the file when the data is unreadable, the split
    unknown, or an object folder missing.
    """
    root = Path(data)
    if (root / "index.json").is_file():
        index = read_index(root / "index.json")
        if split is not None:
            if split not in index.splits:
                raise RsartError(f"{root / 'index.json'}: no split {split!r} (splits: {sorted(index.splits)})")
            ids = list(index.splits[split])
        else:
            ids = list(index.objects)
        objects = {}
        for oid in ids:
            folder = resolve_inside(root, oid)
            if not (folder / "meta.json").is_file():
                raise RsartError(f"{root}: object {oid!r} is listed in index.json but {folder}/meta.json is missing")
            objects[oid] = (folder, read_meta(folder))
        return GroundTruth(root, index.name, index.version, split, objects)
    if (root / "meta.json").is_file():
        meta = read_meta(root)
        return GroundTruth(root, None, None, None, {meta.object_id: (root, meta)})
    raise RsartError(f"{root}: neither a dataset root (index.json) nor an object folder (meta.json)")
