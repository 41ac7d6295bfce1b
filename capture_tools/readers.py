"""RealSense recordings without pyrealsense2: frame folders, colour video + depth folder, ROS1 .bag.

Every reader is a :class:`Recording`: colour ``intrinsics`` (rsart pixel convention: pixel (0, 0) is
the centre of the top-left pixel, as librealsense's ``ppx``/``ppy`` are), ``depth_scale`` (metres
per depth unit) and an iterator of :class:`RawFrame` -- one frame at a time, never the whole
recording in memory. Depth is returned in metres, aligned to the colour image (same size and
pixels); when the streams were recorded unaligned, depth is re-projected into the colour camera
with the recorded depth-to-colour extrinsics (:func:`capture_tools.align.align_depth_to_colour`).

Layout of a frame folder (what RealSense tools / scripts save)::

    intrinsics.json   {"color": {"width", "height", "fx", "fy", "ppx", "ppy", "model", "coeffs"},
                       "depth_scale": 0.001,
                       optional "depth": {...same keys...} and "depth_to_color":
                       {"rotation": [9 numbers, row-major], "translation": [3, metres]} when not aligned}
    color/<name>.png|.jpg     8-bit colour
    depth/<name>.png          16-bit depth units (0 = no measurement), paired with colour by sorted order
    timestamps.csv            optional "name,timestamp_ms" lines

A video recording is the same folder with ``color.mp4`` (or .avi/.mkv) instead of ``color/``.
Errors name the file and what is wrong: :class:`TruncatedFileError`, :class:`MissingIntrinsicsError`,
:class:`StreamMismatchError` (all :class:`CaptureError`, an :class:`rsart.errors.RsartError`).
"""
from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from rsart.camera import Intrinsics
from rsart.errors import RsartError

from .align import align_depth_to_colour

COLOUR_EXT = (".png", ".jpg", ".jpeg")
VIDEO_EXT = (".mp4", ".avi", ".mkv", ".mov")


class CaptureError(RsartError):
    """A raw recording cannot be read."""


class TruncatedFileError(CaptureError):
    """A file of the recording ends early or cannot be decoded."""


class MissingIntrinsicsError(CaptureError):
    """The recording does not say what the camera intrinsics (or depth scale) are."""


class StreamMismatchError(CaptureError):
    """Colour and depth streams do not pair up (different counts or sizes)."""


@dataclass
class RawFrame:
    """One colour frame with its depth. ``rgb`` (H, W, 3) uint8; ``depth`` (H, W) float32 metres aligned to
    the colour pixels (0 = none) or None; ``timestamp`` seconds since the recording's first frame."""

    index: int
    name: str
    timestamp: float
    rgb: np.ndarray
    depth: np.ndarray | None


@dataclass
class StreamCalibration:
    """Colour intrinsics, depth scale and, for unaligned depth, depth intrinsics + (4, 4) depth-to-colour."""

    colour: Intrinsics
    depth_scale: float
    depth: Intrinsics | None = None
    depth_to_colour: np.ndarray | None = None

    def depth_in_colour(self, depth_units: np.ndarray) -> np.ndarray:
        """(H, W) float32 metres in the colour camera from a raw (h, w) depth image in sensor units."""
        d = depth_units.astype(np.float32) * np.float32(self.depth_scale)
        c = self.colour
        if self.depth is None or self.depth_to_colour is None:
            if d.shape != (c.height, c.width):
                raise StreamMismatchError(f"depth image is {d.shape[1]}x{d.shape[0]} but colour is "
                                          f"{c.width}x{c.height} and no depth intrinsics/extrinsics were recorded "
                                          f"to align them")
            return d
        return align_depth_to_colour(d, self.depth, c, self.depth_to_colour)


class Recording:
    """Base of the readers: ``calibration``, ``len()``, iteration over :class:`RawFrame`."""

    source: Path
    calibration: StreamCalibration

    @property
    def intrinsics(self) -> Intrinsics:
        return self.calibration.colour

    @property
    def depth_scale(self) -> float:
        return self.calibration.depth_scale

    def __len__(self) -> int:  # pragma: no cover - overridden
        raise NotImplementedError

    def __iter__(self) -> Iterator[RawFrame]:  # pragma: no cover - overridden
        raise NotImplementedError


# ----------------------------------------------------------------------------- calibration JSON
def _intrinsics_from_dict(d: dict, where: str) -> Intrinsics:
    """librealsense names (ppx, ppy, coeffs) or rsart names (cx, cy, distortion)."""
    if not isinstance(d, dict):
        raise MissingIntrinsicsError(f"{where}: expected an object with width, height, fx, fy, ppx, ppy")
    alias = {"cx": ("ppx", "cx"), "cy": ("ppy", "cy")}
    vals = {}
    for key in ("width", "height", "fx", "fy", "cx", "cy"):
        names = alias.get(key, (key,))
        found = [d[n] for n in names if n in d]
        if not found:
            raise MissingIntrinsicsError(f"{where}: missing '{names[0]}'")
        v = found[0]
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not np.isfinite(v):
            raise MissingIntrinsicsError(f"{where}.{names[0]}: expected a number, got {v!r}")
        vals[key] = v
    if vals["width"] <= 0 or vals["height"] <= 0 or vals["fx"] <= 0 or vals["fy"] <= 0:
        raise MissingIntrinsicsError(f"{where}: width, height, fx, fy must be positive")
    coeffs = d.get("coeffs", d.get("distortion"))
    dist = None
    if coeffs is not None and any(float(x) != 0.0 for x in coeffs):
        dist = tuple(float(x) for x in coeffs)
    return Intrinsics(int(vals["width"]), int(vals["height"]), float(vals["fx"]), float(vals["fy"]),
                      float(vals["cx"]), float(vals["cy"]), dist)


def read_calibration(path: Path) -> StreamCalibration:
    """Parse ``intrinsics.json`` of a frame folder (see the module docstring)."""
    if not path.is_file():
        raise MissingIntrinsicsError(f"{path}: intrinsics file not found (needs the colour intrinsics and "
                                     f"depth_scale)")
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise TruncatedFileError(f"{path}: not valid JSON ({e})") from None
    if not isinstance(d, dict) or "color" not in d:
        raise MissingIntrinsicsError(f"{path}: no 'color' intrinsics")
    colour = _intrinsics_from_dict(d["color"], f"{path}: color")
    ds = d.get("depth_scale")
    if not isinstance(ds, (int, float)) or isinstance(ds, bool) or not ds > 0:
        raise MissingIntrinsicsError(f"{path}: 'depth_scale' (metres per depth unit, e.g. 0.001) missing or "
                                     f"not positive: {ds!r}")
    depth, T = None, None
    if "depth_to_color" in d:
        if "depth" not in d:
            raise MissingIntrinsicsError(f"{path}: 'depth_to_color' given without 'depth' intrinsics")
        depth = _intrinsics_from_dict(d["depth"], f"{path}: depth")
        e = d["depth_to_color"]
        try:
            R = np.asarray(e["rotation"], dtype=np.float64).reshape(3, 3)
            t = np.asarray(e["translation"], dtype=np.float64).reshape(3)
        except (KeyError, TypeError, ValueError):
            raise MissingIntrinsicsError(f"{path}: depth_to_color needs 'rotation' (9 numbers) and "
                                         f"'translation' (3 numbers, metres)") from None
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, t
    return StreamCalibration(colour, float(ds), depth, T)


def write_calibration(path: Path, cal: StreamCalibration) -> None:
    """Write ``intrinsics.json`` in the layout :func:`read_calibration` reads (librealsense key names)."""
    from rsart.io import write_json

    def rs(k: Intrinsics) -> dict:
        return {"width": k.width, "height": k.height, "fx": k.fx, "fy": k.fy, "ppx": k.cx, "ppy": k.cy,
                "model": "brown_conrady", "coeffs": list(k.distortion) if k.distortion else [0.0] * 5}

    d = {"color": rs(cal.colour), "depth_scale": cal.depth_scale}
    if cal.depth is not None and cal.depth_to_colour is not None:
        d["depth"] = rs(cal.depth)
        d["depth_to_color"] = {"rotation": cal.depth_to_colour[:3, :3].ravel().tolist(),
                               "translation": cal.depth_to_colour[:3, 3].tolist()}
    write_json(path, d)


def _timestamps(folder: Path, names: list[str], fps: float) -> list[float]:
    """Seconds per frame from ``timestamps.csv`` (name,timestamp_ms) or frame index / ``fps``."""
    path = folder / "timestamps.csv"
    if not path.is_file():
        return [i / fps for i in range(len(names))]
    table = {}
    with path.open(newline="", encoding="utf-8") as f:
        for row in csv.reader(f):
            if len(row) >= 2 and row[0] != "name":
                try:
                    table[Path(row[0]).stem] = float(row[1]) / 1000.0
                except ValueError:
                    raise CaptureError(f"{path}: bad timestamp {row[1]!r} for {row[0]!r}") from None
    missing = [n for n in names if Path(n).stem not in table]
    if missing:
        raise StreamMismatchError(f"{path}: no timestamp for {len(missing)} frames (first: {missing[0]})")
    t0 = table[Path(names[0]).stem] if names else 0.0
    return [table[Path(n).stem] - t0 for n in names]


def _read_image(path: Path, flags: int) -> np.ndarray:
    data = np.fromfile(str(path), dtype=np.uint8)
    img = cv2.imdecode(data, flags) if data.size else None
    if img is None:
        raise TruncatedFileError(f"{path}: truncated or not a readable image ({data.size} bytes)")
    return img


def _read_depth_units(path: Path, shape_hint: tuple[int, int] | None = None) -> np.ndarray:
    d = _read_image(path, cv2.IMREAD_UNCHANGED)
    if d.dtype != np.uint16 or d.ndim != 2:
        raise CaptureError(f"{path}: depth must be a single-channel 16-bit PNG, got {d.dtype} with shape {d.shape}")
    return d


# ----------------------------------------------------------------------------- frame folders
def _raw_frame(cal: StreamCalibration, depth_files: list[Path], i: int, name: str, t: float, bgr: np.ndarray,
               says: str) -> RawFrame:
    """Frame ``i`` from its (H, W, 3) BGR colour image and depth file ``depth_files[i]`` (if any), aligned
    to colour; :class:`StreamMismatchError` (``says`` + the sizes) when the image is not the calibrated size."""
    c = cal.colour
    if bgr.shape[:2] != (c.height, c.width):
        raise StreamMismatchError(f"{says} {bgr.shape[1]}x{bgr.shape[0]} but the colour intrinsics say "
                                  f"{c.width}x{c.height}")
    depth = cal.depth_in_colour(_read_depth_units(depth_files[i])) if depth_files else None
    return RawFrame(i, name, t, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), depth)


class FrameFolderRecording(Recording):
    """``folder/color/*.png|jpg`` + ``folder/depth/*.png`` + ``folder/intrinsics.json`` (module docstring)."""

    def __init__(self, folder: str | Path, fps: float = 30.0) -> None:
        self.source = Path(folder)
        if not self.source.is_dir():
            raise CaptureError(f"{self.source}: not a folder")
        self.calibration = read_calibration(self.source / "intrinsics.json")
        cdir, ddir = self.source / "color", self.source / "depth"
        if not cdir.is_dir():
            raise CaptureError(f"{cdir}: colour frame folder missing")
        self.colour_files = sorted(p for p in cdir.iterdir() if p.suffix.lower() in COLOUR_EXT)
        self.depth_files = sorted(p for p in ddir.iterdir() if p.suffix.lower() == ".png") if ddir.is_dir() else []
        if not self.colour_files:
            raise CaptureError(f"{cdir}: no colour frames (.png/.jpg)")
        if self.depth_files and len(self.depth_files) != len(self.colour_files):
            raise StreamMismatchError(f"{self.source}: {len(self.colour_files)} colour frames but "
                                      f"{len(self.depth_files)} depth frames")
        self.times = _timestamps(self.source, [p.name for p in self.colour_files], fps)

    def __len__(self) -> int:
        return len(self.colour_files)

    def __iter__(self) -> Iterator[RawFrame]:
        for i, cp in enumerate(self.colour_files):
            bgr = _read_image(cp, cv2.IMREAD_COLOR)
            yield _raw_frame(self.calibration, self.depth_files, i, cp.stem, self.times[i], bgr, f"{cp}: image is")


# ----------------------------------------------------------------------------- video + depth folder
class VideoRecording(Recording):
    """A colour video (OpenCV) + ``depth/*.png`` + ``intrinsics.json`` in one folder (or given explicitly)."""

    def __init__(self, video: str | Path, depth_dir: str | Path | None = None,
                 calibration: str | Path | None = None) -> None:
        video = Path(video)
        self.source = video
        if not video.is_file():
            raise CaptureError(f"{video}: video file not found")
        folder = video.parent
        self.calibration = read_calibration(Path(calibration) if calibration else folder / "intrinsics.json")
        ddir = Path(depth_dir) if depth_dir else folder / "depth"
        self.depth_files = sorted(p for p in ddir.iterdir() if p.suffix.lower() == ".png") if ddir.is_dir() else []
        cap = cv2.VideoCapture(str(video))
        if not cap.isOpened():
            raise TruncatedFileError(f"{video}: OpenCV cannot open this video (truncated or unknown codec)")
        self.fps = cap.get(cv2.CAP_PROP_FPS) or 30.0
        self.n_frames = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        cap.release()
        if self.n_frames <= 0:
            raise TruncatedFileError(f"{video}: the video reports no frames")
        if self.depth_files and len(self.depth_files) != self.n_frames:
            raise StreamMismatchError(f"{video}: {self.n_frames} video frames but {len(self.depth_files)} depth "
                                      f"frames in {ddir}")

    def __len__(self) -> int:
        return self.n_frames

    def __iter__(self) -> Iterator[RawFrame]:
        cap = cv2.VideoCapture(str(self.source))
        try:
            for i in range(self.n_frames):
                ok, bgr = cap.read()
                if not ok:
                    raise TruncatedFileError(f"{self.source}: video ends after {i} of {self.n_frames} frames "
                                             f"(truncated file?)")
                yield _raw_frame(self.calibration, self.depth_files, i, f"{i:06d}", i / self.fps, bgr,
                                 f"{self.source}: frames are")
        finally:
            cap.release()

