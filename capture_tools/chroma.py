"""Chroma key for the green booth: object masks from colour images (and depth, for the pedestal).

Steps (:func:`key_object`):

1. **Calibrate** on the image border (the booth fills it): the green-dominance key
   ``k = (g − max(r, b)) / g`` is ~0.6 on the curtain and the pedestal, ≤ 0 on neutral or warm
   colours and independent of brightness; the background threshold is a fraction of the border's
   median key, so a dimmer or bluer booth recalibrates itself.
2. **Threshold** -> background where ``k`` exceeds it (and the pixel is not black).
3. **Morphology**: open (specks), close (pin holes), keep the connected components that are large
   relative to the biggest one.
4. **GrabCut** (OpenCV) in a band of ``band`` px around the keyed edge: certain foreground inside,
   certain background outside, the band decided by GrabCut's colour models.
5. **Pedestal**: :func:`remove_plane` drops mask pixels whose depth lies on the pedestal plane
   (a pedestal not perfectly green still leaves the mask).

:func:`despill` removes the green cast the booth throws on object edges (g clipped to max(r, b)).
Images are (H, W, 3) uint8 RGB; masks (H, W) bool, True = object.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from rsart.camera import Intrinsics


@dataclass(frozen=True)
class ChromaSettings:
    """``border`` fraction of the image used for calibration; ``key_fraction`` of the border's median key is the
    threshold; ``min_green`` minimum green value (0-255) for a pixel to count as booth; ``band`` GrabCut band (px);
    ``min_component`` fraction of the largest component a component needs to be kept."""

    border: float = 0.04
    key_fraction: float = 0.5
    min_green: int = 25
    open_px: int = 3
    close_px: int = 3
    band: int = 3
    grabcut_iters: int = 2
    min_component: float = 0.05
    grabcut: bool = True


def green_key(rgb: np.ndarray) -> np.ndarray:
    """(H, W) float32 green dominance (g − max(r, b)) / g (0 where g = 0)."""
    x = rgb.astype(np.float32)
    g = x[..., 1]
    return np.where(g > 0, (g - np.maximum(x[..., 0], x[..., 2])) / np.maximum(g, 1.0), 0.0).astype(np.float32)


def border_pixels(img: np.ndarray, frac: float) -> np.ndarray:
    """The values of ``img`` in a frame ``frac`` of the image size wide (any trailing shape)."""
    h, w = img.shape[:2]
    b = max(1, int(round(frac * min(h, w))))
    return np.concatenate([img[:b].reshape(-1, *img.shape[2:]), img[-b:].reshape(-1, *img.shape[2:]),
                           img[b:-b, :b].reshape(-1, *img.shape[2:]), img[b:-b, -b:].reshape(-1, *img.shape[2:])])


def calibrate(rgb: np.ndarray, s: ChromaSettings = ChromaSettings()) -> float:
    """The key threshold of this image: ``key_fraction`` x the median key of the border's green pixels."""
    k = border_pixels(green_key(rgb), s.border)
    green = k[k > 0.1]
    if len(green) < 0.2 * len(k):  # border mostly not booth: fall back to a fixed, conservative threshold
        return 0.3
    return float(s.key_fraction * np.median(green))


def despill(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 with green limited to max(r, b) (removes the booth's green cast)."""
    out = rgb.copy()
    out[..., 1] = np.minimum(rgb[..., 1], np.maximum(rgb[..., 0], rgb[..., 2]))
    return out


def _components(mask: np.ndarray, min_fraction: float) -> np.ndarray:
    n, lab, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if n <= 1:
        return mask
    areas = stats[1:, cv2.CC_STAT_AREA]
    keep = np.flatnonzero(areas >= min_fraction * areas.max()) + 1
    return np.isin(lab, keep)


def key_object(rgb: np.ndarray, s: ChromaSettings = ChromaSettings()) -> np.ndarray:
    """(H, W) bool object mask of a booth image (steps 1-4 of the module docstring)."""
    rgb = rgb[..., :3]
    thr = calibrate(rgb, s)
    booth = (green_key(rgb) > thr) & (rgb[..., 1] >= s.min_green)
    fg = ~booth
    if s.open_px:
        fg = cv2.morphologyEx(fg.astype(np.uint8), cv2.MORPH_OPEN, np.ones((s.open_px, s.open_px), np.uint8)) > 0
    if s.close_px:
        fg = cv2.morphologyEx(fg.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((s.close_px, s.close_px), np.uint8)) > 0
    fg = _components(fg, s.min_component)
    if s.grabcut and fg.any() and not fg.all():
        fg = grabcut_band(rgb, fg, s.band, s.grabcut_iters)
        fg = _components(fg, s.min_component)
    return fg


def grabcut_band(rgb: np.ndarray, fg: np.ndarray, band: int, iters: int = 2) -> np.ndarray:
    """Refine ``fg`` with GrabCut, deciding only pixels within ``band`` px of its edge."""
    k = np.ones((2 * band + 1, 2 * band + 1), np.uint8)
    inner = cv2.erode(fg.astype(np.uint8), k) > 0
    outer = cv2.dilate(fg.astype(np.uint8), k) > 0
    gc = np.full(fg.shape, cv2.GC_BGD, np.uint8)
    gc[outer] = cv2.GC_PR_BGD
    gc[fg] = cv2.GC_PR_FGD
    gc[inner] = cv2.GC_FGD
    if not (gc == cv2.GC_FGD).any() or not (gc == cv2.GC_BGD).any():
        return fg
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.grabCut(cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR), gc, None, bgd, fgd, iters,
                cv2.GC_INIT_WITH_MASK)
    return (gc == cv2.GC_FGD) | (gc == cv2.GC_PR_FGD)


def remove_plane(mask: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics, plane_cam: np.ndarray,
                 tol: float = 0.004) -> np.ndarray:
    """``mask`` without pixels whose depth point lies within ``tol`` m of (or below) the plane.

    ``plane_cam`` (4,): n·x + d = 0 in this view's camera frame with n pointing up (towards the object).
    """
    pts = intrinsics.directions() * depth[..., None]
    signed = pts @ plane_cam[:3] + plane_cam[3]
    on_plane = (depth > 0) & (signed < tol)
    return mask & ~on_plane


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks (1.0 when both are empty)."""
    u = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / u) if u else 1.0
