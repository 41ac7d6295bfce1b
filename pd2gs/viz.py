"""Image strips (PNG) and animations (GIF) of rendered states, written atomically."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def write_strip(images: list[np.ndarray], path: Path) -> Path:
    """Concatenate (H, W, 3) uint8 images side by side (padded to a common height) into a PNG."""
    from rsart.io import write_png_rgb

    h = max(i.shape[0] for i in images)
    padded = [np.pad(i, ((0, h - i.shape[0]), (0, 0), (0, 0)), constant_values=255) for i in images]
    write_png_rgb(path, np.concatenate(padded, axis=1))
    return path


def write_gif(images: list[np.ndarray], path: Path, fps: float = 8.0) -> Path:
    """Animated GIF of (H, W, 3) uint8 frames, looping."""
    import imageio.v2 as imageio

    tmp = path.with_name(path.name + ".tmp.gif")
    imageio.mimsave(tmp, images, duration=1.0 / fps, loop=0)
    tmp.replace(path)
    return path
