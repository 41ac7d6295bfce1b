"""Load raw sources directly: ``rsart.load()`` on a PartNet-Mobility folder, a ``.urdf`` or a USD file.

The source is converted once (the same converters as ``rsart convert``) into a cache folder and the
converted object folder is loaded from there. The cache key is a SHA-256 of the source's *content*
(every file of a PartNet-Mobility folder; for a URDF or USD file the file itself plus the mesh,
material, texture and USD files in its folder tree) and of rsart's version, so an edited source or a
new rsart converts again, and an unchanged one is never converted twice.

Cache folder: the ``cache`` argument, else ``$RSART_CACHE``, else ``$XDG_CACHE_HOME/rsart`` (default
``~/.cache/rsart``). Entries are ``<cache>/<kind>-<name>-<key16>/`` object folders, each written
atomically (a crashed conversion leaves nothing behind); deleting the cache folder is always safe.
"""
from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path
from typing import Callable

from ..errors import RsartError

#: files that can be part of a URDF/USD twin (hashed into the cache key)
ASSET_SUFFIXES = {".obj", ".mtl", ".stl", ".ply", ".dae", ".glb", ".gltf", ".bin", ".png", ".jpg", ".jpeg",
                  ".usd", ".usda", ".usdc", ".usdz", ".urdf", ".xml"}
USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
#: refuse to hash more than this many bytes of a source (a URDF next to a huge folder tree)
MAX_SOURCE_BYTES = 2 * 1024 ** 3


def default_cache() -> Path:
    """``$RSART_CACHE``, else ``$XDG_CACHE_HOME/rsart``, else ``~/.cache/rsart``."""
    if os.environ.get("RSART_CACHE"):
        return Path(os.environ["RSART_CACHE"]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "rsart"


def source_kind(path: Path) -> str | None:
    """"partnet-mobility" (a folder with mobility.urdf), "urdf", "usd", or None for anything else."""
    if path.is_dir() and (path / "mobility.urdf").is_file():
        return "partnet-mobility"
    if path.is_file() and path.suffix.lower() == ".urdf":
        return "urdf"
    if path.is_file() and path.suffix.lower() in USD_SUFFIXES:
        return "usd"
    return None


def _source_files(path: Path, kind: str) -> list[Path]:
    if kind == "partnet-mobility":
        root, files = path, [p for p in path.rglob("*") if p.is_file()]
    else:
        root = path.parent
        files = [path] + [p for p in root.rglob("*") if p.is_file() and p != path
                          and p.suffix.lower() in ASSET_SUFFIXES
                          and not any(part.startswith(".") for part in p.relative_to(root).parts)]
    out = []
    for p in files:  # symlinks leading out of the source folder are not followed
        rp = p.resolve()
        if rp == root.resolve() or root.resolve() in rp.parents:
            out.append(p)
    return sorted(out, key=lambda p: p.relative_to(root).as_posix())


def content_key(path: Path, kind: str) -> str:
    """Hex SHA-256 over rsart's version, the kind, and (relative name, bytes) of every source file."""
    from .. import __version__

    root = path if kind == "partnet-mobility" else path.parent
    h = hashlib.sha256(f"rsart {__version__}\n{kind}\n".encode())
    total = 0
    for p in _source_files(path, kind):
        total += p.stat().st_size
        if total > MAX_SOURCE_BYTES:
            raise RsartError(f"{path}: the source's files exceed {MAX_SOURCE_BYTES >> 30} GiB; convert it with "
                             "`rsart convert` instead")
        h.update(p.relative_to(root).as_posix().encode() + b"\0")
        with open(p, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
        h.update(b"\0")
    return h.hexdigest()


def _convert(path: Path, kind: str, out: Path, progress: Callable | None) -> None:
    if kind == "partnet-mobility":
        from .partnet import convert_partnet

        convert_partnet(path, out, progress=progress)
    elif kind == "urdf":
        from .urdf_twin import convert_urdf

        convert_urdf(path, out, progress=progress)
    else:
        from .usd_twin import convert_usd

        convert_usd(path, out)


def cached_object(path: str | os.PathLike, cache: str | os.PathLike | None = None, *,
                  quiet: bool = False) -> Path:
    """The converted object folder of a raw source ``path`` (converted into the cache on first use).

    Prints one line to stderr and a progress bar over the parts (on a terminal) when it converts;
    nothing when the cache already holds the object (or with ``quiet``).
    """
    path = Path(path)
    kind = source_kind(path)
    if kind is None:
        raise RsartError(f"{path}: not a PartNet-Mobility folder (mobility.urdf), a .urdf or a USD file")
    cache_dir = Path(cache).expanduser() if cache is not None else default_cache()
    if cache_dir.exists() and not cache_dir.is_dir():
        raise RsartError(f"{cache_dir}: the rsart cache must be a folder")
    name = path.name if kind == "partnet-mobility" else path.stem
    safe = "".join(c if c.isalnum() or c in "._-" else "_" for c in name)[:60] or "object"
    out = cache_dir / f"{kind}-{safe}-{content_key(path, kind)[:16]}"
    if (out / "meta.json").is_file():
        return out
    if not quiet:
        print(f"rsart: converting {kind} {path} once into {out} (cached by content)", file=sys.stderr)
    bar = None

    def progress(done: int, total: int, part: str) -> None:
        nonlocal bar
        if quiet:
            return
        if bar is None:
            from tqdm import tqdm

            bar = tqdm(total=total, desc=f"{name} parts", unit="part", file=sys.stderr, leave=False, disable=None)
        bar.set_postfix_str(part, refresh=False)
        bar.update(done - bar.n)

    try:
        _convert(path, kind, out, progress)
    except RsartError as e:
        if (out / "meta.json").is_file():  # another process finished the same conversion first
            return out
        raise RsartError(f"{path}: cannot load it directly: {e}") from None
    finally:
        if bar is not None:
            bar.close()
    return out
