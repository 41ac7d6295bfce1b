"""RGB-only initialisation of the canonical Gaussians from silhouettes (ours; ``TrainConfig.init="hull"``).

3DGS starts from SfM points; PD²GS inherits that. Starting instead from Gaussians spread uniformly in
the object's box works for bulky objects but not for thin ones (a desk lamp's arms are 1–2 px at
160×120): every box Gaussian also covers background, the loss drives their opacity to zero, and the
opacity reset at iteration 1000 then prunes the whole field (measured: 4888 -> 9 Gaussians, test PSNR
18 dB). A visual hull needs only the images and the known cameras: a pixel is foreground when its
colour differs from the estimated background colour; a voxel of the box is kept for a state when it
projects onto foreground in (nearly) every view of that state that sees it. The union of the
per-state hulls holds each part in every position it takes, as the canonical field must.

Frames: voxel centres in the world (object) frame; cameras OpenCV (``Frame.K``, ``Frame.w2c``).
"""
from __future__ import annotations

import numpy as np
import torch


def foreground(rgb: torch.Tensor, background, thresh: float = 0.08) -> np.ndarray:
    """(H, W) bool: pixels whose colour differs from ``background`` (RGB in [0, 1]) by > ``thresh``
    in some channel."""
    bg = torch.as_tensor(background, dtype=rgb.dtype)
    return ((rgb - bg).abs().amax(-1) > thresh).numpy()


def visual_hull(frames, background, lo, hi, resolution: int = 64, min_agree: float = 0.9,
                thresh: float = 0.08, max_views: int = 30) -> np.ndarray:
    """(M, 3) centres of the voxels in the union over states of the per-state visual hulls.

    frames: training ``Frame`` s (rgb (H, W, 3), K, w2c, state); lo, hi: (3,) box corners; the box is cut
    into ``resolution`` voxels along its longest side. Per state at most ``max_views`` evenly spaced
    views vote; a view votes only on voxels in front of it and inside the image.
    """
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    step = float((hi - lo).max()) / resolution
    axes = [lo[i] + step * (np.arange(max(1, int(np.ceil((hi[i] - lo[i]) / step)))) + 0.5) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    keep = np.zeros(len(grid), bool)
    states = sorted({f.state for f in frames})
    for s in states:
        fs = [f for f in frames if f.state == s]
        fs = [fs[i] for i in np.unique(np.linspace(0, len(fs) - 1, min(max_views, len(fs))).round().astype(int))]
        votes = np.zeros(len(grid))
        seen = np.zeros(len(grid))
        for f in fs:
            fg = foreground(f.rgb, background, thresh)
            h, w = fg.shape
            w2c = f.w2c.double().numpy()
            cam = grid @ w2c[:3, :3].T + w2c[:3, 3]
            z = cam[:, 2]
            K = f.K.double().numpy()
            with np.errstate(divide="ignore", invalid="ignore"):
                u = K[0, 0] * cam[:, 0] / z + K[0, 2]
                v = K[1, 1] * cam[:, 1] / z + K[1, 2]
            ok = (z > 1e-6) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
            ui, vi = u[ok].astype(int), v[ok].astype(int)
            seen[ok] += 1
            votes[ok] += fg[vi, ui]
        keep |= (seen > 0) & (votes >= min_agree * np.maximum(seen, 1))
    return grid[keep] if keep.any() else np.zeros((0, 3))


def hull_points(frames, background, lo, hi, n: int, seed: int, resolution: int = 64,
                min_voxels: int = 50) -> torch.Tensor | None:
    """(n, 3) float32 points drawn uniformly in the hull's voxels, or None when the hull has fewer than
    ``min_voxels`` voxels (e.g. a background the colour test cannot separate; callers fall back to the box)."""
    centres = visual_hull(frames, background, lo, hi, resolution)
    if len(centres) < min_voxels:
        return None
    step = float((np.asarray(hi) - np.asarray(lo)).max()) / resolution
    rng = np.random.default_rng(seed)
    pick = centres[rng.integers(0, len(centres), n)]
    return torch.as_tensor(pick + rng.uniform(-0.5, 0.5, (n, 3)) * step, dtype=torch.float32)
