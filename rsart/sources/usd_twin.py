"""Import a USD articulation (rsart's own or authored by other tools, e.g. Isaac Sim) as an object folder.

``rsart convert usd TWIN.usd --out DIR`` calls :func:`convert_usd`: the USD is read with
:func:`rsart.usd.read_usd` (Y-up stages rotated to Z-up, lengths scaled to metres, bodies posed
away from rest moved back to joint values 0) and written by :func:`rsart.twin_io.write_object`,
which also derives the RS-Art interaction states from the joint limits.
"""
from __future__ import annotations

from pathlib import Path

from ..checks import is_safe_id, make_safe_id
from ..errors import RsartError
from ..io import is_empty_dir
from ..usd import read_usd

USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")


def default_object_id(src: Path) -> str:
    """A safe object id from a file name: invalid characters become '_' (e.g. 'my door.usd' -> 'my_door')."""
    return make_safe_id(Path(src).stem, "usd-object")


def convert_usd(src: str | Path, out: str | Path, *, object_id: str | None = None, category: str | None = None,
                overwrite: bool = False) -> Path:
    """Read the USD articulation ``src`` and write the object folder ``out``; returns ``out``.

    A USD that rsart wrote keeps its object id, category and source (provenance, with
    ``converted_from`` added); otherwise ``object_id`` defaults to the file stem (made a safe id),
    ``category`` to "unknown". Units are
    metres whatever the stage's ``metersPerUnit`` — except a twin rsart wrote from a unitless
    ("scene"-unit) object, which stays "scene". Raises RsartError (naming the prim path) on an
    invalid USD; ``out`` is then left untouched (the folder is built atomically).
    """
    src, out = Path(src), Path(out)
    if src.suffix.lower() not in USD_SUFFIXES:
        raise RsartError(f"{src}: not a USD file (expected one of {', '.join(USD_SUFFIXES)})")
    from ..usd_read import read_usd_object_info

    info = read_usd_object_info(src) if src.is_file() else {}
    oid = object_id if object_id is not None else (info.get("object_id") or default_object_id(src))
    if not is_safe_id(oid):
        raise RsartError(f"object id {oid!r} is not a safe id (letters, digits, '_', '.', '-')")
    if category is not None and not category.strip():
        raise RsartError("category must be a non-empty string")
    if out.exists() and not overwrite and not is_empty_dir(out):
        raise RsartError(f"{out}: already exists and is not empty (pass overwrite to replace it)")
    twin = read_usd(src)
    from ..twin_io import write_object
    from ..usd_read import read_usd_units

    source = ({**info["source"], "converted_from": {"kind": "usd", "file": src.name}} if "source" in info
              else {"kind": "usd", "id": src.stem, "file": src.name})
    write_object(twin, out, object_id=oid, category=category or info.get("category") or "unknown",
                 source=source, units=read_usd_units(src), overwrite=overwrite)
    return out
