"""Training frames: images and cameras of an RS-Art object (via ``rsart.load``) resized for training.

A ``Frame`` holds one view at the training resolution; intrinsics are rescaled with
``rsart.camera.Camera.scaled`` (pixel-centre convention kept).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from rsart.camera import pinhole_unproject
from rsart.errors import RsartError


class DataError(RsartError, ValueError):
    """Invalid training input (message names the path or field)."""


@dataclass
class Frame:
    """One view. rgb (H, W, 3) float32 in [0, 1]; depth (H, W) metres (0 = none) or None;
    K (3, 3), w2c (4, 4) float32 (OpenCV); state: index into the run's state list."""

    rgb: torch.Tensor
    depth: torch.Tensor | None
    K: torch.Tensor
    w2c: torch.Tensor
    state: int
    split: str
    view_id: str = ""

    @property
    def size(self) -> tuple[int, int]:
        """(width, height)."""
        return self.rgb.shape[1], self.rgb.shape[0]


def parse_size(text: str) -> tuple[int, int]:
    """'160x120' -> (160, 120)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise DataError(f"--size must look like 160x120, got {text!r}") from None
    if w < 8 or h < 8 or w > 4096 or h > 4096:
        raise DataError(f"--size {text!r} out of range (8..4096 per side)")
    return w, h


def _resize(img: np.ndarray, size: tuple[int, int], nearest: bool) -> np.ndarray:
    import cv2

    if img.shape[1] == size[0] and img.shape[0] == size[1]:
        return img
    interp = cv2.INTER_NEAREST if nearest else cv2.INTER_AREA
    return cv2.resize(img, size, interpolation=interp)


def load_frames(object_dir: str | Path, states: list[str] | None, size: tuple[int, int],
                with_depth: bool = False) -> tuple[list[str], list[Frame]]:
    """Frames of the captured ``states`` (default: all captured) of one RS-Art object.

    Returns (state ids, frames); raises DataError for a missing object, unknown or
    uncaptured states.
    """
    import rsart
    from rsart.errors import RsartError

    path = Path(object_dir)
    if not (path / "meta.json").is_file():
        raise DataError(f"{path}: not an RS-Art object folder (no meta.json)")
    try:
        obj = rsart.load(path)
    except RsartError as e:
        raise DataError(str(e)) from None
    states = states or obj.captured_states
    if not states:
        raise DataError(f"{path}: no captured states (no states/*/cameras.json)")
    frames = []
    for k, sid in enumerate(states):
        if sid not in obj.states:
            raise DataError(f"{path}: unknown state {sid!r} (has {', '.join(obj.states)})")
        if not obj.states[sid].captured:
            raise DataError(f"{path}: state {sid!r} has no captured views")
        for v in obj.states[sid].views:
            cam = v.camera.scaled(*size)
            rgb = _resize(v.rgb, size, nearest=False).astype(np.float32) / 255.0
            depth = None
            if with_depth and v.has_depth:
                depth = torch.from_numpy(_resize(v.depth, size, nearest=True).astype(np.float32))
            frames.append(Frame(torch.from_numpy(rgb), depth, torch.from_numpy(cam.K).float(),
                                torch.from_numpy(cam.w2c).float(), k, v.split, v.id))
    return list(states), frames


def object_bounds(object_dir: str | Path, states: list[str]) -> tuple[torch.Tensor, torch.Tensor] | None:
    """Axis-aligned bounding box (lo, hi) (metres, world) of the object's twin over ``states``,
    or None when the twin cannot be read."""
    import rsart

    try:
        obj = rsart.load(Path(object_dir))
        boxes = []
        for sid in states:
            for m in obj.twin.posed_meshes(obj.states[sid].values):
                boxes.append(np.asarray(m.bounds))
    except Exception:  # noqa: BLE001 - the twin is optional for training
        return None
    if not boxes:
        return None
    b = np.stack(boxes)
    return torch.tensor(b[:, 0].min(0)).float(), torch.tensor(b[:, 1].max(0)).float()


def backproject_frames(frames: list[Frame], max_points: int = 200_000) -> tuple[torch.Tensor, torch.Tensor]:
    """World points (M, 3) and colours (M, 3) from every frame with depth."""
    pts, cols = [], []
    for f in frames:
        if f.depth is None:
            continue
        h, w = f.depth.shape
        v, u = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
        ok = f.depth > 0
        z = f.depth[ok]
        pc = pinhole_unproject(f.K, u[ok], v[ok], z)
        c2w = torch.linalg.inv(f.w2c)
        pts.append(pc @ c2w[:3, :3].T + c2w[:3, 3])
        cols.append(f.rgb[ok])
    if not pts:
        raise DataError("depth initialisation asked for, but no view has a depth image")
    p, c = torch.cat(pts), torch.cat(cols)
    if p.shape[0] > max_points:
        idx = torch.randperm(p.shape[0], generator=torch.Generator().manual_seed(0))[:max_points]
        p, c = p[idx], c[idx]
    return p, c


def camera_bounds(frames: list[Frame], points: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Axis-aligned box (lo, hi) for initialisation: the points' box if given, else a box around
    the point closest to all camera optical axes, sized by the mean camera distance / 3."""
    if points is not None:
        lo, hi = points.min(0).values, points.max(0).values
        pad = 0.05 * (hi - lo).norm()
        return lo - pad, hi + pad
    a = torch.zeros(3, 3)
    b = torch.zeros(3)
    centres = []
    for f in frames:
        c2w = torch.linalg.inv(f.w2c).double()
        o, d = c2w[:3, 3], c2w[:3, 2]
        m = torch.eye(3, dtype=torch.float64) - torch.outer(d, d)
        a += m.float()
        b += (m @ o).float()
        centres.append(o.float())
    target = torch.linalg.solve(a, b)
    radius = float(torch.stack([(c - target).norm() for c in centres]).mean()) / 3
    return target - radius, target + radius
