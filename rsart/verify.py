"""Dataset integrity: SHA-256 checksums of every file, recorded beside ``index.json``.

``checksums.sha256`` uses the ``sha256sum`` text format (``<hex>  <relative path>``, sorted,
POSIX separators), so ``sha256sum -c checksums.sha256`` works too. Hidden files and the
checksum file itself are not listed.

Untrusted datasets: a file or folder whose symlinks lead out of the root is reported (``outside``) and
never opened, hashed or listed (:func:`rsart.io.check_inside`); symlinks that stay inside are followed.
Besides checksums, :func:`verify` checks every image listed by a state's ``cameras.json`` against its
camera's width x height, reading only the PNG header (Pillow decodes no pixels for ``.size``).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from .errors import RsartError
from .io import atomic_write_text, check_inside, sha256_file

CHECKSUMS = "checksums.sha256"


def _walk(root: Path) -> tuple[list[str], list[str]]:
    """(files, outside): relative POSIX paths of the (non-hidden) files under ``root``, and of the files
    and folders whose symlinks lead out of it (not opened, not listed). Folder links inside are followed
    once each (a link loop is not walked twice)."""
    files, outside, seen = [], [], set()
    for dirpath, dirnames, filenames in os.walk(root, followlinks=True):
        here = Path(dirpath)
        real = here.resolve()
        if real in seen:
            dirnames[:] = []
            continue
        seen.add(real)
        keep = []
        for d in sorted(d for d in dirnames if not d.startswith(".")):
            try:
                check_inside(root, here / d)
                keep.append(d)
            except RsartError:
                outside.append((here / d).relative_to(root).as_posix())
        dirnames[:] = keep
        for f in filenames:
            if f.startswith(".") or (here == root and f == CHECKSUMS):
                continue
            rel = (here / f).relative_to(root).as_posix()
            try:
                check_inside(root, here / f)
                files.append(rel)
            except RsartError:
                outside.append(rel)
    return sorted(files), sorted(outside)


def _files(root: Path) -> list[str]:
    return _walk(root)[0]


def compute_checksums(root: str | os.PathLike) -> dict[str, str]:
    """Relative POSIX path -> SHA-256 hex of every (non-hidden) file under ``root``."""
    root = Path(root)
    return {rel: sha256_file(root / rel) for rel in _files(root)}


def write_checksums(root: str | os.PathLike) -> Path:
    """(Re)write ``<root>/checksums.sha256`` for every file under ``root``; returns its path."""
    root = Path(root)
    outside = _walk(root)[1]
    if outside:
        raise RsartError(f"{root / outside[0]}: leads out of {root} (through a symlink); refused without reading it"
                         + (f" (and {len(outside) - 1} more)" if len(outside) > 1 else ""))
    sums = compute_checksums(root)
    path = root / CHECKSUMS
    atomic_write_text(path, "".join(f"{h}  {rel}\n" for rel, h in sums.items()))
    return path


def read_checksums(root: str | os.PathLike) -> dict[str, str]:
    path = Path(root) / CHECKSUMS
    if not path.is_file():
        raise RsartError(f"{path}: no checksum file (write one with rsart.verify.write_checksums)")
    out = {}
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        parts = line.split("  ", 1)
        if len(parts) != 2 or len(parts[0]) != 64:
            raise RsartError(f"{path}:{n}: malformed line (expected '<sha256>  <path>')")
        out[parts[1]] = parts[0]
    return out


@dataclass
class VerifyReport:
    """Outcome of :func:`verify`: files missing, extra (unrecorded), corrupt (checksum differs), of the wrong
    size (``"rel: problem"``), and ``outside``: entries whose symlinks lead out of the root (refused unread)."""

    checked: int = 0
    missing: list[str] = field(default_factory=list)
    extra: list[str] = field(default_factory=list)
    corrupt: list[str] = field(default_factory=list)
    wrong_size: list[str] = field(default_factory=list)
    outside: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not (self.missing or self.extra or self.corrupt or self.wrong_size or self.outside)


def _image_size(path: Path) -> tuple[int, int] | None:
    """(width, height) from the image header (no pixel decoding), None when unreadable."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            return im.size
    except Exception:  # not an image, truncated header, decompression-bomb guard: reported by the caller
        return None


def check_image_sizes(root: Path, present: set[str]) -> list[str]:
    """Each image of every ``states/<id>/cameras.json`` among ``present`` against its camera's size."""
    from .format import read_cameras

    out = []
    for rel in sorted(r for r in present if r.endswith("/cameras.json") and "/states/" in f"/{r}"):
        try:
            cams = read_cameras(root / rel)
        except RsartError as e:
            out.append(f"{rel}: {e}")
            continue
        want = (cams.intrinsics.width, cams.intrinsics.height)
        state = rel.rsplit("/", 1)[0]
        for v in cams.views:
            for kind in ("rgb", "depth", "mask"):
                img = f"{state}/{kind}/{v.id}.png"
                if img not in present:
                    continue
                size = _image_size(root / img)
                if size is None:
                    out.append(f"{img}: not a readable image")
                elif tuple(size) != want:
                    out.append(f"{img}: {size[0]}x{size[1]} pixels, its camera ({rel}) is {want[0]}x{want[1]}")
    return out


def verify(root: str | os.PathLike) -> VerifyReport:
    """Check every file under ``root`` against the recorded checksums, and every image against its camera."""
    root = Path(root)
    recorded = read_checksums(root)
    files, outside = _walk(root)
    present = set(files)
    rep = VerifyReport(outside=outside)
    out_set = set(outside)
    for rel, h in recorded.items():
        if rel in out_set or any(rel.startswith(o + "/") for o in outside):
            continue  # reported as outside; never opened
        if rel not in present:
            rep.missing.append(rel)
            continue
        rep.checked += 1
        if sha256_file(root / rel) != h:
            rep.corrupt.append(rel)
    rep.extra = sorted(present - set(recorded))
    rep.wrong_size = check_image_sizes(root, present)
    return rep
