"""Writing generated objects and the named ``rsart-synth`` benchmark.

``rsart-synth`` (version 1) mirrors the composition of the paper's evaluation:

* ``rs-art-like``: RS-Art's 6 categories x 3 instances (seeds 0, 1, 2) = 18 objects;
* ``partnet-like``: the 8 PartNet-Mobility categories x 3 instances = 24 objects, two movable
  parts each except the seed-2 instance of faucet, oven, storage and table (three movable parts);
* ``five-part``: storage and table objects with five movable parts (2 each);
* ``all`` (46 objects), and by movable-part count ``one-part``, ``two-part``, ``three-part``,
  ``five-part``; ``multi-part`` = three or more movable parts.

The suite is written in a temporary sibling folder and renamed into place when complete, with
``index.json`` and ``checksums.sha256`` (for ``rsart verify``).
"""
from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from ...errors import RsartError
from ...format import DatasetIndex, ObjectMeta, write_index
from ...io import atomic_dir
from .registry import CATEGORIES, PARTNET_LIKE, RS_ART_LIKE, VERSION, Generated, generate

SUITE_NAME = "rsart-synth"
SUITE_SEEDS = (0, 1, 2)
FIVE_PART = (("storage", 0), ("storage", 1), ("table", 0), ("table", 1))
COUNT_SPLITS = {1: "one-part", 2: "two-part", 3: "three-part", 5: "five-part"}


@dataclass(frozen=True)
class SuiteItem:
    """One object of a suite: ``category``, ``seed`` and forced ``movable`` count (None = default)."""

    category: str
    seed: int
    movable: int | None = None


def suite_items() -> list[SuiteItem]:
    """The 46 objects of rsart-synth v1, in index order."""
    items = [SuiteItem(c, s) for c in RS_ART_LIKE + PARTNET_LIKE for s in SUITE_SEEDS]
    items += [SuiteItem(c, s, 5) for c, s in FIVE_PART]
    return items


def write_generated(g: Generated, out_dir: str | os.PathLike, overwrite: bool = False) -> ObjectMeta:
    """Write a generated object as an object folder at ``out_dir`` (through ``rsart.twin_io.write_object``)."""
    from ...twin_io import write_object

    c = CATEGORIES[g.category]
    extra = {"procedural": {"family": c.family, "movable_parts": len(g.twin.parts) - 1,
                            "labels": {p.name: p.extra.get("label", p.name) for p in g.twin.parts}}}
    return write_object(g.twin, out_dir, object_id=g.object_id, category=g.category, source=g.source,
                        extra_meta=extra, overwrite=overwrite)


def _write_item(args: tuple[SuiteItem, str]) -> tuple[str, str, int]:
    item, root = args
    g = generate(item.category, item.seed, item.movable)
    write_generated(g, Path(root) / g.object_id)
    return g.object_id, item.category, len(g.twin.parts) - 1


def build_index(rows: list[tuple[str, str, int]], forced: set[str]) -> DatasetIndex:
    """The suite's index: objects in order, family / count splits (``rows`` = (object_id, category, movable))."""
    objects = [r[0] for r in rows]
    splits: dict[str, list[str]] = {"all": list(objects), "rs-art-like": [], "partnet-like": [], "five-part": []}
    for oid, cat, n in rows:
        if oid in forced:
            if n == 5:
                splits["five-part"].append(oid)
            continue
        splits[CATEGORIES[cat].family].append(oid)
    for n, name in COUNT_SPLITS.items():
        ids = [oid for oid, _, k in rows if k == n]
        if ids:
            splits[name] = ids
    splits["multi-part"] = [oid for oid, _, k in rows if k >= 3]
    splits = {k: v for k, v in splits.items() if v}
    extra = {"generator": "rsart.sources.procedural", "generator_version": VERSION,
             "categories": {oid: cat for oid, cat, _ in rows}, "movable_parts": {oid: n for oid, _, n in rows},
             "units": "m"}
    return DatasetIndex(SUITE_NAME, VERSION, objects, splits, extra=extra)


def write_suite(root: str | os.PathLike, workers: int = 2, overwrite: bool = False,
                items: list[SuiteItem] | None = None) -> DatasetIndex:
    """Write the rsart-synth dataset (twins only) at ``root``: object folders, index.json, checksums.

    ``workers`` > 1 uses a process pool over objects. Returns the index.
    """
    from ...verify import write_checksums

    items = suite_items() if items is None else items
    if workers < 1:
        raise RsartError(f"workers must be >= 1, got {workers}")
    with atomic_dir(root, overwrite=overwrite) as tmp:
        jobs = [(it, str(tmp)) for it in items]
        if workers == 1:
            rows = [_write_item(j) for j in jobs]
        else:
            with ProcessPoolExecutor(max_workers=workers) as ex:
                rows = list(ex.map(_write_item, jobs))
        forced = {generate_id(it) for it in items if it.movable is not None}
        index = build_index(rows, forced)
        write_index(index, tmp / "index.json")
        write_checksums(tmp)
    return index


def generate_id(it: SuiteItem) -> str:
    from .registry import object_id

    return object_id(it.category, it.seed, it.movable)
