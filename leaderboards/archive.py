"""Safe extraction of an uploaded submission archive (zip).

Refused, with a message naming the entry: not a zip; too many entries; an absolute path, a drive letter,
a backslash, a NUL or a ``..`` component (zip-slip); a symlink or any non-regular entry; duplicate names;
a declared or an *actual* uncompressed size over the limit; a compression ratio over ``max_ratio``
(zip bomb — sizes are counted while inflating, the headers are not trusted). The whole archive has limits
too, also checked while inflating: its expanded size (``max_unpacked_bytes``) and its overall ratio
(bytes written / size of the zip, ``max_total_ratio`` once more than ``ratio_floor_bytes`` are written), so a
bomb split into many small entries (1000 × 1 MiB of zeros) is stopped after a few tens of MiB. Extraction
goes to a temporary sibling folder renamed into place only when complete; a crash leaves only that
``.*.partial`` folder, which the server removes at start-up.
"""
from __future__ import annotations

import os
import shutil
import stat
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from rsart.errors import RsartError

CHUNK = 1 << 16


class ArchiveError(RsartError):
    """An unsafe or unusable archive; the message names the entry."""


@dataclass(frozen=True)
class ArchiveLimits:
    max_upload_bytes: int = 200 * 1024 ** 2     # the zip itself
    max_unpacked_bytes: int = 1024 ** 3         # everything inflated
    max_entries: int = 20000
    max_ratio: float = 200.0                    # inflated / compressed, per entry (only above 1 MiB)
    max_total_ratio: float = 50.0               # everything inflated / the zip's size
    ratio_floor_bytes: int = 32 * 1024 ** 2     # ... checked once this much is inflated (small text is fine)


def _check_name(name: str) -> PurePosixPath:
    if not name or "\x00" in name or "\\" in name:
        raise ArchiveError(f"entry {name!r}: invalid characters in the name")
    p = PurePosixPath(name)
    if p.is_absolute() or (len(name) > 1 and name[1] == ":"):
        raise ArchiveError(f"entry {name!r}: absolute path")
    if any(part == ".." for part in p.parts):
        raise ArchiveError(f"entry {name!r}: '..' escapes the archive folder (zip-slip)")
    return p


def _entry_kind(info: zipfile.ZipInfo) -> str:
    fmt = stat.S_IFMT(info.external_attr >> 16)  # 0 when the archiver recorded no file type (plain file)
    if fmt == stat.S_IFLNK:
        return "symlink"
    if info.is_dir() or fmt == stat.S_IFDIR:
        return "dir"
    if fmt not in (0, stat.S_IFREG):
        return "special"
    return "file"


def extract_zip(zip_path: str | Path, dest: str | Path, limits: ArchiveLimits = ArchiveLimits()) -> Path:
    """Extract ``zip_path`` into the new folder ``dest`` (must not exist) → ``dest``; ArchiveError if unsafe."""
    zip_path, dest = Path(zip_path), Path(dest)
    zip_size = max(zip_path.stat().st_size, 1)
    if zip_path.stat().st_size > limits.max_upload_bytes:
        raise ArchiveError(f"archive is {zip_path.stat().st_size} bytes; the limit is {limits.max_upload_bytes}")
    if not zipfile.is_zipfile(zip_path):
        raise ArchiveError("the upload is not a zip archive")
    if dest.exists():
        raise ArchiveError(f"{dest}: already exists")
    tmp = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".partial", dir=dest.parent))
    try:
        with zipfile.ZipFile(zip_path) as zf:
            infos = zf.infolist()
            if len(infos) > limits.max_entries:
                raise ArchiveError(f"archive has {len(infos)} entries; the limit is {limits.max_entries}")
            seen: set[str] = set()
            declared = 0
            for info in infos:
                p = _check_name(info.filename)
                kind = _entry_kind(info)
                if kind in ("symlink", "special"):
                    raise ArchiveError(f"entry {info.filename!r}: {kind} entries are not allowed")
                key = str(p).rstrip("/")
                if key in seen and kind != "dir":
                    raise ArchiveError(f"entry {info.filename!r}: duplicate name")
                seen.add(key)
                declared += info.file_size
            if declared > limits.max_unpacked_bytes:
                raise ArchiveError(f"archive unpacks to {declared} bytes; the limit is {limits.max_unpacked_bytes}")
            total = 0
            root = tmp.resolve()
            for info in infos:
                p = _check_name(info.filename)
                target = (tmp / p).resolve()
                if root != target and root not in target.parents:
                    raise ArchiveError(f"entry {info.filename!r}: escapes the archive folder")
                if info.is_dir():
                    target.mkdir(parents=True, exist_ok=True)
                    continue
                target.parent.mkdir(parents=True, exist_ok=True)
                written = 0
                with zf.open(info) as src, open(target, "xb") as dst:
                    while True:
                        buf = src.read(CHUNK)
                        if not buf:
                            break
                        written += len(buf)
                        total += len(buf)
                        if total > limits.max_unpacked_bytes:
                            raise ArchiveError(f"entry {info.filename!r}: archive unpacks to more than "
                                               f"{limits.max_unpacked_bytes} bytes (zip bomb?)")
                        if written > 1 << 20 and written > limits.max_ratio * max(info.compress_size, 1):
                            raise ArchiveError(f"entry {info.filename!r}: compression ratio above "
                                               f"{limits.max_ratio:.0f} (zip bomb?)")
                        if total > limits.ratio_floor_bytes and total > limits.max_total_ratio * zip_size:
                            raise ArchiveError(f"entry {info.filename!r}: the archive inflates to more than "
                                               f"{limits.max_total_ratio:.0f} times its {zip_size} bytes "
                                               "(zip bomb?)")
                        dst.write(buf)
    except zipfile.BadZipFile as e:
        shutil.rmtree(tmp, ignore_errors=True)
        raise ArchiveError(f"corrupt zip archive: {e}") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    os.replace(tmp, dest)
    return dest


def find_submission_file(folder: Path) -> Path:
    """``submission.json`` at the archive root, or inside its single top-level folder."""
    top = folder / "submission.json"
    if top.is_file():
        return top
    subs = [p for p in folder.iterdir() if p.is_dir() and not p.name.startswith("__MACOSX")]
    if len(subs) == 1 and (subs[0] / "submission.json").is_file():
        return subs[0] / "submission.json"
    raise ArchiveError("no submission.json at the archive root (or in its single top-level folder)")
