"""The category registry: category id -> generator, and :func:`generate` (category, seed) -> object.

Object ids: ``<category>-<seed:04d>`` (e.g. ``drawer-0003``); when the number of movable parts is
forced (``movable=5``) the id is ``<category>-<movable>p-<seed:04d>`` (e.g. ``storage-5p-0000``).
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ...errors import RsartError
from ...kinematics import Twin
from . import partnet_like as P
from . import rs_art_like as R
from .builder import ObjectBuilder
from .catalogue import CATALOGUE

GENERATOR = "rsart.sources.procedural"
VERSION = "2"


@dataclass(frozen=True)
class Category:
    """A generator: ``family`` ("rs-art-like" | "partnet-like"), ``movable`` (min, max) movable parts."""

    id: str
    family: str
    make: Callable[[ObjectBuilder, np.random.Generator, int | None], None]
    movable: tuple[int, int]
    description: str


_MAKERS: dict[str, Callable[[ObjectBuilder, np.random.Generator, int | None], None]] = {
    "drawer": R.make_drawer,
    "desk_lamp": R.make_desk_lamp,
    "eyeglasses_rs": lambda b, r, n: R.make_eyeglasses(b, r, n, "rs"),
    "floppy_drive": R.make_floppy_drive,
    "woven_basket": R.make_woven_basket,
    "stand": R.make_stand,
    "box": P.make_box,
    "door": P.make_door,
    "eyeglasses": lambda b, r, n: R.make_eyeglasses(b, r, n, "partnet"),
    "faucet": P.make_faucet,
    "oven": P.make_oven,
    "refrigerator": P.make_refrigerator,
    "storage": P.make_storage,
    "table": P.make_table,
}
CATEGORIES: dict[str, Category] = {c.id: Category(c.id, c.family, _MAKERS[c.id], c.movable, c.description)
                                   for c in CATALOGUE}

RS_ART_LIKE = [c for c, v in CATEGORIES.items() if v.family == "rs-art-like"]
PARTNET_LIKE = [c for c, v in CATEGORIES.items() if v.family == "partnet-like"]
THREE_PART = ("faucet", "oven", "storage", "table")   # PartNet-like categories whose seed%3==2 instance has 3 movable parts


@dataclass
class Generated:
    """A generated object: its twin, id, category and the meta.json ``source`` record."""

    twin: Twin
    object_id: str
    category: str
    source: dict


def object_id(category: str, seed: int, movable: int | None = None) -> str:
    return f"{category}-{movable}p-{seed:04d}" if movable else f"{category}-{seed:04d}"


def default_movable(category: str, seed: int) -> int | None:
    """The PartNet-like protocol: 2 movable parts, 3 for the seed % 3 == 2 instance of THREE_PART categories."""
    c = CATEGORIES[category]
    if c.family != "partnet-like":
        return None
    if category in THREE_PART and seed % 3 == 2:
        return 3
    return max(c.movable[0], min(2, c.movable[1]))


def generate(category: str, seed: int, movable: int | None = None) -> Generated:
    """Build the ``category`` instance of ``seed`` (deterministic); ``movable`` forces the movable-part count."""
    if category not in CATEGORIES:
        raise RsartError(f"unknown category {category!r} (known: {', '.join(CATEGORIES)})")
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise RsartError(f"seed must be a non-negative integer, got {seed!r}")
    c = CATEGORIES[category]
    if movable is not None and not (c.movable[0] <= movable <= c.movable[1]):
        raise RsartError(f"{category}: movable parts must be in [{c.movable[0]}, {c.movable[1]}], got {movable}")
    oid = object_id(category, seed, movable)
    n = movable if movable is not None else default_movable(category, seed)
    rng = np.random.default_rng([zlib.crc32(category.encode()), int(seed), int(movable or 0)])
    b = ObjectBuilder(oid)
    c.make(b, rng, n)
    twin = b.build()
    src = {"kind": "procedural", "id": f"{category}:{seed}" + (f":{movable}p" if movable else ""),
           "generator": GENERATOR, "version": VERSION, "category": category, "seed": int(seed)}
    if movable:
        src["movable_parts"] = int(movable)
    return Generated(twin, oid, category, src)
