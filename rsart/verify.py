"""Dataset integrity: SHA-256 checksums of every file, recorded beside ``index.json``.

``checksums.sha256`` uses the ``sha256sum`` text format (``<hex>  <relative path>``, sorted,
POSIX separators), so ``sha256sum -c checksums.sha256`` works too. Hidden files and the
checksum file itself are not listed.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from .errors import RsartError
from .io import atomic_write_text, sha256_file

CHECKSUMS = "checksums.sha256"


def _files(root: Path) -> list[str]:
    out = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
        for f in filenames:
            if f.startswith(".") or (Path(dirpath) == root and f == CHECKSUMS):
                continue
            out.append((Path(dirpath) / f).relative_to(root).as_posix())
    return sorted(out)


def compute_checksums(root: str | os.PathLike) -> dict[str, str]:
    """Relative POSIX path -> SHA-256 hex of every (non-hidden) file under ``root``."""
    root = Path(root)
    return {rel: sha256_file(root / rel) for rel in _files(root)}


def write_checksums(root: str | os.PathLike) -> Path:
    """(Re)write ``<root>/checksums.sha256`` for every file under ``root``; returns its path."""
    root = Path(root)
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
    """Outcome of :func:`verify`: files missing, extra (unrecorded) and corrupt (checksum differs)."""

    checked: int = 0
    missing: list[str] = field(default_factory=list)
    extra: list[str] = field(default_factory=list)
    corrupt: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not (self.missing or self.extra or self.corrupt)


def verify(root: str | os.PathLike) -> VerifyReport:
    """Check every file under ``root`` against the recorded checksums."""
    root = Path(root)
    recorded = read_checksums(root)
    present = set(_files(root))
    rep = VerifyReport()
    for rel, h in recorded.items():
        if rel not in present:
            rep.missing.append(rel)
            continue
        rep.checked += 1
        if sha256_file(root / rel) != h:
            rep.corrupt.append(rel)
    rep.extra = sorted(present - set(recorded))
    return rep
