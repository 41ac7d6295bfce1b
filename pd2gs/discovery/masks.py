"""Part masks from point prompts (paper Sec. 3.4): visibility sets, FPS prompts, mask providers.

Images are (H, W[, 3]) arrays; pixel coordinates are (u, v) = (column, row) with integer pixel centres
(rsart.camera / pd2gs.render convention).

Providers (``make_provider``): ``grabcut`` (OpenCV GrabCut seeded with the prompts; the visible set
Omega+ is its "probable foreground"), ``sam`` (segment_anything with a local checkpoint; imported only
when chosen), ``oracle`` (the dataset's true part mask, the upper-bound ablation).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from rsart.errors import RsartError


def visibility_sets(label_weights: np.ndarray, part: int, tau_vis: float, eps: float = 1e-6
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(Omega+, Omega-) bool (H, W) for ``part`` from per-label weights (H, W, L).

    Omega+: w_p / (max_{q != p} w_q + eps) > tau_vis (and w_p > 0); Omega-: w_p == 0.
    """
    wp = label_weights[..., part]
    others = np.delete(label_weights, part, axis=-1)
    wmax = others.max(axis=-1) if others.shape[-1] else np.zeros_like(wp)
    pos = (wp > 0) & (wp / (wmax + eps) > tau_vis)
    return pos, wp <= 0


def farthest_point_sampling(points: np.ndarray, k: int, seed: int = 0) -> np.ndarray:
    """Indices of ``k`` farthest-point samples of (M, d) points, seeded start.

    Hand-written (10 lines): open3d's FPS returns points, not indices, and has no seed.
    """
    m = len(points)
    if m == 0 or k <= 0:
        return np.zeros(0, dtype=np.int64)
    k = min(k, m)
    pts = points.astype(np.float64)
    idx = [int(np.random.default_rng(seed).integers(m))]
    d = np.linalg.norm(pts - pts[idx[0]], axis=1)
    for _ in range(k - 1):
        i = int(np.argmax(d))
        idx.append(i)
        d = np.minimum(d, np.linalg.norm(pts - pts[i], axis=1))
    return np.asarray(idx, dtype=np.int64)


def sample_prompts(pos: np.ndarray, neg: np.ndarray, n_pos: int = 10, n_neg: int = 20, seed: int = 0
                   ) -> tuple[np.ndarray, np.ndarray]:
    """FPS prompts: (n_pos, 2) positive and (n_neg, 2) negative (u, v) pixels from two bool masks."""
    out = []
    for mask, k in ((pos, n_pos), (neg, n_neg)):
        vu = np.argwhere(mask)
        uv = vu[:, ::-1]
        out.append(uv[farthest_point_sampling(uv, k, seed)])
    return out[0], out[1]


MaskProvider = Callable[..., np.ndarray]


class MaskProviderError(RsartError, RuntimeError):
    """A mask provider cannot run as configured (missing package, checkpoint or true masks)."""


@dataclass
class GrabCutProvider:
    """GrabCut seeded by the prompts: disks of ``radius`` px around positives = foreground, around
    negatives = background; Omega+ = probable foreground, the rest probable background."""

    iters: int = 5
    radius: int = 3
    seed: int = 0

    def __call__(self, rgb: np.ndarray, pos_uv: np.ndarray, neg_uv: np.ndarray, *, support: np.ndarray,
                 **_) -> np.ndarray:
        if len(pos_uv) == 0:
            return np.zeros(rgb.shape[:2], dtype=bool)
        mask = np.where(support, cv2.GC_PR_FGD, cv2.GC_PR_BGD).astype(np.uint8)
        for (u, v) in neg_uv:
            cv2.circle(mask, (int(u), int(v)), self.radius, int(cv2.GC_BGD), -1)
        for (u, v) in pos_uv:
            cv2.circle(mask, (int(u), int(v)), self.radius, int(cv2.GC_FGD), -1)
        bgd, fgd = np.zeros((1, 65)), np.zeros((1, 65))
        img = np.ascontiguousarray(rgb[..., ::-1], dtype=np.uint8)  # OpenCV wants BGR
        cv2.setRNGSeed(self.seed)  # GrabCut's k-means draws from OpenCV's global RNG: seed it for repeatability
        try:
            cv2.grabCut(img, mask, None, bgd, fgd, self.iters, cv2.GC_INIT_WITH_MASK)
        except cv2.error:  # degenerate colour models (e.g. one-colour image): fall back to the seeds
            pass
        return (mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD)


class SamProvider:
    """Segment Anything with point prompts (positive label 1, negative 0); needs the ``segment_anything``
    package and a local checkpoint file."""

    def __init__(self, checkpoint: str | None, model_type: str = "vit_b"):
        try:
            from segment_anything import SamPredictor, sam_model_registry
        except ImportError:
            raise MaskProviderError("mask_provider='sam' needs the segment_anything package "
                               "(pip install segment-anything) and sam_checkpoint=<local .pth>") from None
        if not checkpoint:
            raise MaskProviderError("mask_provider='sam' needs sam_checkpoint=<path to a local SAM .pth file>")
        from pathlib import Path
        if not Path(checkpoint).is_file():
            raise MaskProviderError(f"SAM checkpoint {checkpoint} does not exist")
        self.predictor = SamPredictor(sam_model_registry[model_type](checkpoint=checkpoint))
        self._key = None

    def __call__(self, rgb: np.ndarray, pos_uv: np.ndarray, neg_uv: np.ndarray, *, view_key=None, **_) -> np.ndarray:
        if len(pos_uv) == 0:
            return np.zeros(rgb.shape[:2], dtype=bool)
        if view_key is None or view_key != self._key:
            self.predictor.set_image(np.ascontiguousarray(rgb, dtype=np.uint8))
            self._key = view_key
        pts = np.concatenate([pos_uv, neg_uv]).astype(np.float32)
        lab = np.concatenate([np.ones(len(pos_uv)), np.zeros(len(neg_uv))]).astype(np.int32)
        masks, _, _ = self.predictor.predict(point_coords=pts, point_labels=lab, multimask_output=False)
        return masks[0].astype(bool)


@dataclass
class OracleProvider:
    """The dataset's true mask of the true part that overlaps the visible set Omega+ most."""

    def __call__(self, rgb: np.ndarray, pos_uv: np.ndarray, neg_uv: np.ndarray, *, support: np.ndarray,
                 true_mask: np.ndarray | None = None, **_) -> np.ndarray:
        if true_mask is None:
            raise MaskProviderError("mask_provider='oracle' needs the dataset's part masks (states/<s>/mask/)")
        vals = true_mask[support & (true_mask > 0)]
        if vals.size == 0:
            return np.zeros(true_mask.shape, dtype=bool)
        return true_mask == np.bincount(vals).argmax()


def make_provider(name: str, *, grabcut_iters: int = 5, sam_checkpoint: str | None = None,
                  sam_model_type: str = "vit_b", seed: int = 0) -> MaskProvider:
    """The mask provider called ``name`` ("grabcut" | "sam" | "oracle")."""
    if name == "grabcut":
        return GrabCutProvider(iters=grabcut_iters, seed=seed)
    if name == "sam":
        return SamProvider(sam_checkpoint, sam_model_type)
    if name == "oracle":
        return OracleProvider()
    raise ValueError(f"unknown mask provider {name!r}")
