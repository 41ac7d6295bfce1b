"""Load raw sources directly: ``rsart.load()`` on a PartNet-Mobility folder, a ``.urdf`` or a USD file.

The source is converted once (the same converters as ``rsart convert``) into a cache folder and the
converted object folder is loaded from there. The cache key is a SHA-256 of the source's *content*
(every file of a PartNet-Mobility folder; for a URDF the file, the meshes it names and their MTL and
texture files; for a USD file every layer and asset it depends on, as ``UsdUtils.ComputeAllDependencies``
finds them) and of rsart's version, so an edited source or a
new rsart converts again, and an unchanged one is never converted twice.

Cache folder: the ``cache`` argument, else ``$RSART_CACHE``, else ``$XDG_CACHE_HOME/rsart`` (default
``~/.cache/rsart``). Entries are ``<cache>/<kind>-<name>-<key16>/`` object folders, each written
atomically (a crashed conversion leaves nothing behind); deleting the cache folder is always safe.
"""
from __future__ import annotations

import hashlib
import os
import re
import sys
from pathlib import Path
from typing import Callable

from ..errors import RsartError

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


def _inside(p: Path, root: Path) -> bool:
    p = p.resolve()
    return (p == root or root in p.parents) and p.is_file()


def _obj_side_files(obj: Path, root: Path) -> list[Path]:
    """MTL files an OBJ names (``mtllib``) and the images those name (``map_*``), inside ``root`` only."""
    out = []
    try:
        text = obj.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return out
    for mtl in re.findall(r"(?m)^\s*mtllib\s+(.+?)\s*$", text):
        mp = obj.parent / mtl
        if not _inside(mp, root):
            continue
        out.append(mp)
        mtext = mp.read_text(encoding="utf-8", errors="replace")
        for img in re.findall(r"(?m)^\s*map_\w+\s+(?:-\S+\s+\S+\s+)*(.+?)\s*$", mtext):
            ip = mp.parent / img
            if _inside(ip, root):
                out.append(ip)
    return out


def _urdf_files(path: Path) -> list[Path]:
    """The URDF, the mesh files it names (inside its folder, as the reader resolves them) and their MTLs/images."""
    import defusedxml.ElementTree as DET

    root = path.parent.resolve()
    files = [path]
    try:
        xml = DET.fromstring(path.read_bytes(), forbid_dtd=True)
    except Exception:  # the converter reports what is wrong with the file
        return files
    for el in xml.iter("mesh"):
        fn = el.get("filename") or ""
        if fn.startswith("package://"):  # the same rule as rsart.urdf's mesh lookup
            fn = fn.split("/", 3)[-1] if fn.count("/") >= 3 else fn[len("package://"):]
        if fn.startswith("file://"):
            fn = fn[len("file://"):]
        mp = path.parent / fn
        if os.path.isabs(fn) or not _inside(mp, root):
            continue
        files.append(mp)
        if mp.suffix.lower() == ".obj":
            files += _obj_side_files(mp, root)
    return files


def _usd_files(path: Path) -> list[Path]:
    """The USD file and every layer and asset it depends on (``UsdUtils.ComputeAllDependencies``)."""
    try:
        from pxr import UsdUtils

        layers, assets, _ = UsdUtils.ComputeAllDependencies(str(path))
    except Exception:  # unreadable: the converter reports it
        return [path]
    found = [Path(lay.realPath) for lay in layers if lay.realPath] + [Path(a) for a in assets]
    return [path] + [p for p in found if p.is_file()]


def _source_files(path: Path, kind: str) -> list[Path]:
    """Every file whose content the conversion depends on, sorted, without duplicates."""
    if kind == "partnet-mobility":
        root = path.resolve()
        files = [p for p in path.rglob("*") if _inside(p, root)]  # symlinks out of the folder are not followed
    elif kind == "urdf":
        files = _urdf_files(path)
    else:
        files = _usd_files(path)
    return sorted({p.resolve() for p in files}, key=lambda p: p.as_posix())


def content_key(path: Path, kind: str) -> str:
    """Hex SHA-256 over rsart's version, the kind, and (relative name, bytes) of every source file."""
    from .. import __version__

    base = (path if kind == "partnet-mobility" else path.parent).resolve()
    h = hashlib.sha256(f"rsart {__version__}\n{kind}\n".encode())
    total = 0
    for p in _source_files(path, kind):
        total += p.stat().st_size
        if total > MAX_SOURCE_BYTES:
            raise RsartError(f"{path}: the source's files exceed {MAX_SOURCE_BYTES >> 30} GiB; convert it with "
                             "`rsart convert` instead")
        h.update((p.relative_to(base).as_posix() if base in p.parents else p.as_posix()).encode() + b"\0")
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
    from ..extras import require  # converting (not loading a cached object) needs the importer's extra

    if kind == "usd":
        require("usd", f"loading {path.name} (a USD file)")
    else:  # watertight copies need open3d
        require("render", f"loading {path} (converted with the {kind} importer)", modules=("open3d",))
    if not quiet:
        print(f"rsart: converting {kind} {path} once into {out} (cached by content)", file=sys.stderr)
    from .urdf_twin import PartProgress

    bar = PartProgress(f"{name} parts", enabled=not quiet)
    try:
        _convert(path, kind, out, bar)
    except RsartError as e:
        if (out / "meta.json").is_file():  # another process finished the same conversion first
            return out
        raise RsartError(f"{path}: cannot load it directly: {e}") from None
    finally:
        bar.close()
    return out
