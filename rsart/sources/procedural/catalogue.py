"""The procedural categories as plain data (ids, family, movable-part range, description).

Kept apart from the generators so that ``rsart generate --help`` can list them without importing the
geometry stack (trimesh, manifold3d); :mod:`.registry` attaches a generator to each entry.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CategoryInfo:
    """A category: ``family`` ("rs-art-like" | "partnet-like"), ``movable`` (min, max) movable parts."""

    id: str
    family: str
    movable: tuple[int, int]
    description: str


#: Every category, in the order of docs/procedural.md and the CLI's help.
CATALOGUE: tuple[CategoryInfo, ...] = (
    CategoryInfo("drawer", "rs-art-like", (1, 3), "desktop drawer unit, 1-3 prismatic drawers"),
    CategoryInfo("desk_lamp", "rs-art-like", (2, 3), "architect desk lamp, 2-3 chained revolute links"),
    CategoryInfo("eyeglasses_rs", "rs-art-like", (2, 2), "eyeglasses, 2 revolute temples"),
    CategoryInfo("floppy_drive", "rs-art-like", (2, 2), "floppy-disk drive: prismatic tray + revolute flap"),
    CategoryInfo("woven_basket", "rs-art-like", (1, 2), "woven basket, 1-2 revolute lids or a handle"),
    CategoryInfo("stand", "rs-art-like", (2, 2), "folding phone/laptop stand, 2 chained revolute hinges"),
    CategoryInfo("box", "partnet-like", (1, 3), "storage box with hinged lid flaps"),
    CategoryInfo("door", "partnet-like", (2, 2), "door leaf + lever handle in a frame"),
    CategoryInfo("eyeglasses", "partnet-like", (2, 2), "eyeglasses, 2 revolute temples"),
    CategoryInfo("faucet", "partnet-like", (2, 3), "faucet: revolute handles (+ swivel spout)"),
    CategoryInfo("oven", "partnet-like", (2, 3), "oven: drop-down door + rotary knobs"),
    CategoryInfo("refrigerator", "partnet-like", (2, 2), "refrigerator, 2 doors (side by side or co-axial)"),
    CategoryInfo("storage", "partnet-like", (2, 5), "storage furniture: doors + drawers"),
    CategoryInfo("table", "partnet-like", (2, 5), "desk/table with drawers and doors"),
)
