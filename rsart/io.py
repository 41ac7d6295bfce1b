"""File I/O shared by every rsart module: atomic writes, PNG images, checksums.

Atomicity: every writer writes to a temporary file in the destination folder and then
``os.replace``-s it into place, so an interrupted run never leaves a truncated file.
Image conventions (DESIGN.md §3): RGB 8-bit PNG; depth 16-bit PNG in units of
``depth_scale`` metres (0 = no measurement); masks 8-bit PNG with part index + 1, 0 = background.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from .errors import RsartError

DEPTH_MAX_UNITS = 65535


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    atomic_write_bytes(path, text.encode("utf-8"))


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def dumps_json(obj: Any) -> str:
    """Deterministic JSON text (2-space indent, trailing newline, NaN forbidden)."""
    return json.dumps(obj, indent=2, default=_json_default, allow_nan=False) + "\n"


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as JSON atomically (numpy arrays/scalars are converted)."""
    atomic_write_text(path, dumps_json(obj))


def read_json(path: str | os.PathLike) -> Any:
    """Read a JSON file; raise :class:`RsartError` naming the file on a missing file or bad JSON."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RsartError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise RsartError(f"{path}: cannot read ({e})") from None
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as e:
        raise RsartError(f"{path}: invalid JSON at line {e.lineno} column {e.colno}: {e.msg}") from None
    except ValueError as e:
        raise RsartError(f"{path}: {e}") from None


def _reject_constant(name: str) -> Any:
    raise ValueError(f"non-finite number {name} is not allowed in JSON")


def is_empty_dir(path: str | os.PathLike) -> bool:
    """True for an existing folder without any entry (not a symlink)."""
    p = Path(path)
    return p.is_dir() and not p.is_symlink() and next(p.iterdir(), None) is None


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike, overwrite: bool = False) -> Iterator[Path]:
    """Build a folder atomically: yields a temporary sibling folder, renamed to ``path`` on success.

    On an exception the temporary folder is removed and ``path`` is untouched. An existing *empty*
    folder is accepted (users often create the output folder first); anything else that exists
    needs ``overwrite``, and is replaced only after the new folder is complete.
    """
    path = Path(path)
    if path.exists() and not overwrite and not is_empty_dir(path):
        raise RsartError(f"{path}: already exists and is not empty (pass overwrite to replace it)")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent))
    try:
        yield tmp
        if path.exists():
            old = path.with_name(f".{path.name}.old-{os.getpid()}")
            os.replace(path, old)
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _encode_png(img: np.ndarray) -> bytes:
    import cv2

    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise RsartError("PNG encoding failed")
    return buf.tobytes()


def _decode_png(path: str | os.PathLike, flags: int) -> np.ndarray:
    import cv2

    data = np.fromfile(str(path), dtype=np.uint8) if Path(path).exists() else None
    if data is None:
        raise RsartError(f"{path}: file not found")
    img = cv2.imdecode(data, flags)
    if img is None:
        raise RsartError(f"{path}: not a readable image")
    return img


def write_png_rgb(path: str | os.PathLike, rgb: np.ndarray) -> None:
    """Write an (H, W, 3) uint8 RGB image (or (H, W, 4) RGBA) as PNG, atomically."""
    import cv2

    rgb = np.asarray(rgb)
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] not in (3, 4):
        raise ValueError(f"expected (H, W, 3|4) uint8, got {rgb.shape} {rgb.dtype}")
    code = cv2.COLOR_RGB2BGR if rgb.shape[2] == 3 else cv2.COLOR_RGBA2BGRA
    atomic_write_bytes(path, _encode_png(cv2.cvtColor(rgb, code)))


def read_png_rgb(path: str | os.PathLike) -> np.ndarray:
    """Read a PNG/JPG as (H, W, 3) uint8 RGB."""
    import cv2

    img = _decode_png(path, cv2.IMREAD_COLOR)
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def depth_to_units(depth_m: np.ndarray, depth_scale: float = 0.001) -> np.ndarray:
    """Metric depth (H, W) float metres -> uint16 units of ``depth_scale`` m; invalid/out of range -> 0."""
    d = np.asarray(depth_m, dtype=np.float64)
    units = np.round(d / depth_scale)
    bad = ~np.isfinite(units) | (units <= 0) | (units > DEPTH_MAX_UNITS)
    units[bad] = 0
    return units.astype(np.uint16)


def write_depth_png(path: str | os.PathLike, depth_m: np.ndarray, depth_scale: float = 0.001) -> None:
    """Write metric depth (H, W) in metres as a 16-bit PNG of ``depth_scale``-metre units (0 = none)."""
    atomic_write_bytes(path, _encode_png(depth_to_units(depth_m, depth_scale)))


def read_depth_png(path: str | os.PathLike, depth_scale: float = 0.001) -> np.ndarray:
    """Read a 16-bit depth PNG as (H, W) float32 metres (0 = no measurement)."""
    import cv2

    img = _decode_png(path, cv2.IMREAD_UNCHANGED)
    if img.dtype != np.uint16 or img.ndim != 2:
        raise RsartError(f"{path}: expected a single-channel 16-bit depth PNG, got {img.dtype} {img.shape}")
    return (img.astype(np.float32) * np.float32(depth_scale)).astype(np.float32)


def write_mask_png(path: str | os.PathLike, mask: np.ndarray) -> None:
    """Write an (H, W) uint8 part mask (part index + 1, 0 = background) as PNG."""
    mask = np.asarray(mask)
    if mask.dtype != np.uint8 or mask.ndim != 2:
        raise ValueError(f"expected (H, W) uint8 mask, got {mask.shape} {mask.dtype}")
    atomic_write_bytes(path, _encode_png(mask))


def read_mask_png(path: str | os.PathLike) -> np.ndarray:
    """Read an 8-bit part mask PNG as (H, W) uint8."""
    import cv2

    img = _decode_png(path, cv2.IMREAD_UNCHANGED)
    if img.dtype != np.uint8 or img.ndim != 2:
        raise RsartError(f"{path}: expected a single-channel 8-bit mask PNG, got {img.dtype} {img.shape}")
    return img


def sha256_file(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file, read in chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def resolve_inside(root: str | os.PathLike, rel: str) -> Path:
    """Resolve ``rel`` against ``root`` and refuse anything (absolute, ``..``, symlink) that leaves ``root``.

    This is rsart's one inside-the-folder rule (mesh paths of twins and submissions, URDF meshes, every
    file ``rsart.load``, ``verify``, ``validate`` and the renderer read). Resolving only reads links, it
    opens nothing, so a file outside ``root`` is refused without being read. Symlinks whose target stays
    inside ``root`` are allowed.
    """
    root_r = Path(root).resolve()
    if os.path.isabs(rel):
        raise RsartError(f"{rel}: absolute paths are not allowed (must be relative to {root})")
    try:
        p = (root_r / rel).resolve()
    except (OSError, RuntimeError) as e:  # a symlink loop
        raise RsartError(f"{rel}: cannot be resolved ({e})") from None
    if p != root_r and root_r not in p.parents:
        raise RsartError(f"{rel}: path leaves {root}")
    return p


def check_inside(root: str | os.PathLike, path: str | os.PathLike) -> Path:
    """``path`` (a path under ``root``) unchanged when it stays inside ``root`` after following every
    symlink on the way; else RsartError naming it. See :func:`resolve_inside`; nothing is opened."""
    try:
        resolve_inside(root, os.path.relpath(path, root))
    except RsartError:
        raise RsartError(f"{path}: leads out of {root} (through a symlink or '..'); refused without "
                         "reading it") from None
    return Path(path)


def copy_folder_contents(src: str | os.PathLike, dst: str | os.PathLike, skip: tuple[str, ...] = ()) -> None:
    """Copy every entry of ``src`` (except names in ``skip`` and hidden ones) into ``dst``.

    Refuses symbolic links at any depth (an object folder must be self-contained; following a link
    could copy files from outside the folder the user named).
    """
    src, dst = Path(src), Path(dst)
    for dirpath, dirnames, filenames in os.walk(src):
        rel = Path(dirpath).relative_to(src)
        if rel == Path("."):
            dirnames[:] = [d for d in dirnames if d not in skip and not d.startswith(".")]
            filenames = [f for f in filenames if f not in skip and not f.startswith(".")]
        for name in dirnames + filenames:
            if (Path(dirpath) / name).is_symlink():
                raise RsartError(f"{Path(dirpath) / name}: symbolic links are not copied "
                                 "(object folders must be self-contained)")
        (dst / rel).mkdir(parents=True, exist_ok=True)
        for f in filenames:
            shutil.copy2(Path(dirpath) / f, dst / rel / f)
