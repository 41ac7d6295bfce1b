"""Image files in the peers' input layouts (every write atomic, through rsart.io).

* RGBA PNG (PARIS, ArtGS): RGB from the capture, alpha 255 on the object (rsart mask > 0), 0 elsewhere.
* Segmented colour (DTArt): RGB with the background set to black.
* Object mask (DTArt): 8-bit, 255 on the object.
* Depth (DTArt, ArtGS): 16-bit millimetres, 0 off the object and where the capture has no depth.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from rsart.dataset import View
from rsart.errors import RsartError
from rsart.io import atomic_write_bytes, write_depth_png


def _png(img: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise RsartError("PNG encoding failed")
    return buf.tobytes()


def object_mask(view: View) -> np.ndarray:
    """(H, W) bool: pixels of the object (any part)."""
    return view.mask > 0


def write_rgba(path: Path, view: View) -> None:
    rgb, fg = view.rgb, object_mask(view)
    rgba = np.dstack([rgb, np.where(fg, 255, 0).astype(np.uint8)])
    atomic_write_bytes(path, _png(cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGRA)))


def write_segmented_rgb(path: Path, view: View) -> None:
    rgb = view.rgb * object_mask(view)[..., None]
    atomic_write_bytes(path, _png(cv2.cvtColor(rgb.astype(np.uint8), cv2.COLOR_RGB2BGR)))


def write_object_mask(path: Path, view: View) -> None:
    atomic_write_bytes(path, _png(np.where(object_mask(view), 255, 0).astype(np.uint8)))


def write_object_depth(path: Path, view: View) -> None:
    """Depth in mm, zero off the object (the booth and floor are not part of the scene to reconstruct)."""
    d = np.where(object_mask(view), view.depth, 0.0).astype(np.float32)
    write_depth_png(path, d, 0.001)
