"""What ``rsart render`` accepts and how it becomes object folders under the output root.

* an object folder (``meta.json`` + ``twin/``): copied (meta.json, twin/ and any other top-level
  files except ``states/`` and ``render.json``) to ``<out>/<object_id>/``, or rendered in place
  when it already is that folder;
* a dataset root (``index.json``): every object folder it lists;

Nothing outside the folder given is read: its ``meta.json``/``index.json`` and object folders must stay
inside after following symlinks (:func:`rsart.io.check_inside`), and the copy refuses every symlink.
* a bare URDF (``.urdf``) or USD (``.usd``, ``.usda``, ``.usdc``) file: read into a twin and
  written as ``<out>/<stem>/`` with the RS-Art states (:func:`rsart.twin_io.write_object`).
"""
from __future__ import annotations

import re
from pathlib import Path

from ..errors import RsartError
from ..format import meta_to_dict, read_index, read_meta
from ..io import atomic_dir, check_inside, copy_folder_contents

URDF_SUFFIXES = (".urdf",)
USD_SUFFIXES = (".usd", ".usda", ".usdc")
_SKIP = ("states", "render.json")


def _twin_signature(meta_dict: dict) -> dict:
    """The parts of a meta.json that define the twin (rendering may only add protocol states)."""
    d = dict(meta_dict)
    d["states"] = [s for s in d.get("states", []) if "protocol" not in s]
    return d


def _copy_object(src: Path, dest: Path, overwrite: bool, root: Path) -> Path:
    src_meta = read_meta(check_inside(root, src / "meta.json"))
    if dest.exists() and (dest / "meta.json").exists():
        if src.resolve() == dest.resolve():
            return dest
        if _twin_signature(meta_to_dict(read_meta(dest))) == _twin_signature(meta_to_dict(src_meta)):
            return dest  # resuming: this twin was copied by an earlier run
        if not overwrite:
            raise RsartError(f"{dest}: holds a different object than {src}; use another --out or pass --overwrite")
    with atomic_dir(dest, overwrite=True) as tmp:
        copy_folder_contents(src, tmp, skip=_SKIP)
    return dest


def safe_object_id(stem: str) -> str:
    """A format-safe object id from a file stem (letters, digits, '_', '.', '-')."""
    s = re.sub(r"[^A-Za-z0-9_.\-]", "_", stem).lstrip("._-") or "object"
    return s[:128]


def _from_twin_file(src: Path, out_root: Path, overwrite: bool) -> Path:
    from ..twin_io import write_object

    oid = safe_object_id(src.stem)
    dest = out_root / oid
    kind = "urdf" if src.suffix.lower() in URDF_SUFFIXES else "usd"
    if dest.exists() and (dest / "meta.json").exists() and not overwrite:
        meta = read_meta(dest)
        if meta.source.get("kind") == kind and meta.source.get("file") == src.name:
            return dest  # resuming
        raise RsartError(f"{dest}: already holds another object; use another --out or pass --overwrite")
    if kind == "urdf":
        from ..urdf import read_urdf
        twin = read_urdf(src)
    else:
        from ..usd import read_usd
        twin = read_usd(src)
    write_object(twin, dest, object_id=oid, category="unknown", source={"kind": kind, "id": oid, "file": src.name},
                 overwrite=overwrite)
    return dest


def object_dirs(src: str | Path, out_root: Path, overwrite: bool = False) -> list[Path]:
    """Object folders under ``out_root`` ready to render for the input ``src`` (see module docstring)."""
    src = Path(src)
    if not src.exists():
        raise RsartError(f"{src}: no such file or folder")
    if src.is_dir():
        if (src / "meta.json").is_file():
            meta = read_meta(check_inside(src, src / "meta.json"))
            return [_copy_object(src, out_root / meta.object_id, overwrite, src)]
        if (src / "index.json").is_file():  # nothing outside the root is read (symlinks in copies: refused)
            idx = read_index(check_inside(src, src / "index.json"))
            return [_copy_object(check_inside(src, src / oid), out_root / oid, overwrite, src) for oid in idx.objects]
        raise RsartError(f"{src}: neither an object folder (meta.json) nor a dataset root (index.json)")
    suffix = src.suffix.lower()
    if suffix in URDF_SUFFIXES + USD_SUFFIXES:
        return [_from_twin_file(src, out_root, overwrite)]
    raise RsartError(f"{src}: expected an object folder, a dataset root, a .urdf or a .usd/.usda/.usdc file")
