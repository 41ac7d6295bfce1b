"""Frame selection: sharp, well-exposed frames spread around the object.

Scores per frame (computed on one frame at a time while streaming a recording):

* sharpness -- variance of the Laplacian of the grey image inside the object mask (hand-held
  motion blur lowers it);
* exposure -- fraction of object pixels that are neither crushed (< 8) nor clipped (> 247).

:func:`select_frames` drops frames below ``min_sharp_ratio`` x the median sharpness or with poor
exposure, then picks ``n`` frames spread along the path: with known camera directions (after SfM)
by farthest-point sampling of viewing directions, otherwise evenly in time (an operator walking one
circle at a steady pace spreads time evenly over azimuth), each slot taking its sharpest frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass
class FrameScore:
    """Quality of one frame: ``sharpness`` (Laplacian variance), ``exposure`` (fraction well exposed)."""

    index: int
    timestamp: float
    sharpness: float
    exposure: float


def score_frame(index: int, timestamp: float, rgb: np.ndarray, mask: np.ndarray | None = None) -> FrameScore:
    """Score (H, W, 3) uint8 ``rgb`` (inside ``mask`` when given and non-empty)."""
    grey = cv2.cvtColor(rgb[..., :3], cv2.COLOR_RGB2GRAY)
    lap = cv2.Laplacian(grey, cv2.CV_64F)
    sel = mask if mask is not None and mask.any() else np.ones(grey.shape, bool)
    if mask is not None and mask.any():
        sel = cv2.erode(mask.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0  # not the silhouette edge
        if not sel.any():
            sel = mask
    g = grey[sel]
    return FrameScore(index, timestamp, float(lap[sel].var()), float(np.mean((g > 8) & (g < 247))))


def select_frames(scores: list[FrameScore], n: int, directions: dict[int, np.ndarray] | None = None,
                  min_sharp_ratio: float = 0.5, min_exposure: float = 0.9) -> list[int]:
    """Indices of up to ``n`` selected frames (sorted). ``directions``: frame index -> (3,) viewing direction."""
    if not scores:
        return []
    med = float(np.median([s.sharpness for s in scores]))
    good = [s for s in scores if s.sharpness >= min_sharp_ratio * med and s.exposure >= min_exposure]
    if len(good) < n:  # not enough good frames: fall back to the best of all
        good = sorted(scores, key=lambda s: -s.sharpness)[: max(n, len(good))]
    if len(good) <= n:
        return sorted(s.index for s in good)
    if directions:
        cand = [s for s in good if s.index in directions]
        D = np.array([directions[s.index] / np.linalg.norm(directions[s.index]) for s in cand])
        first = int(np.argmax([s.sharpness for s in cand]))
        chosen = [first]
        dist = 1 - D @ D[first]
        while len(chosen) < min(n, len(cand)):
            nxt = int(np.argmax(dist))
            chosen.append(nxt)
            dist = np.minimum(dist, 1 - D @ D[nxt])
        return sorted(cand[i].index for i in chosen)
    good = sorted(good, key=lambda s: s.timestamp)
    t = np.array([s.timestamp for s in good])
    edges = np.linspace(t[0], t[-1] + 1e-9, n + 1)
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        slot = [s for s in good if a <= s.timestamp < b]
        if slot:
            out.append(max(slot, key=lambda s: s.sharpness).index)
    return sorted(out)
