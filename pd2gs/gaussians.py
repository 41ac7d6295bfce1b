"""The canonical 3D Gaussian field: stored parameters, activations and initialisation.

Stored (optimised) parameters, N Gaussians, world frame, metres:
    means (N, 3); quats (N, 4) (w, x, y, z), normalised on use; log_scales (N, 3) with the
    per-axis standard deviation s = exp(log_scales) (covariance R diag(s)^2 R^T, the 3DGS
    squared-scale convention); color_logits (N, 3) with RGB = sigmoid; opacity_logits (N,)
    with opacity = sigmoid.
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

PARAM_NAMES = ("means", "quats", "log_scales", "color_logits", "opacity_logits")


def inverse_sigmoid(x: torch.Tensor) -> torch.Tensor:
    return torch.log(x / (1 - x))


class CanonicalGaussians(nn.Module):
    """Canonical Gaussians; parameters are replaced wholesale by densification."""

    def __init__(self, means: torch.Tensor, log_scales: torch.Tensor, colors: torch.Tensor,
                 opacity: float = 0.1, quats: torch.Tensor | None = None):
        super().__init__()
        n = means.shape[0]
        if quats is None:
            quats = torch.zeros(n, 4)
            quats[:, 0] = 1
        self.means = nn.Parameter(means.float().clone())
        self.quats = nn.Parameter(quats.float().clone())
        self.log_scales = nn.Parameter(log_scales.float().clone())
        self.color_logits = nn.Parameter(inverse_sigmoid(colors.float().clamp(0.02, 0.98)))
        self.opacity_logits = nn.Parameter(inverse_sigmoid(torch.full((n,), float(opacity))))

    @property
    def num(self) -> int:
        return self.means.shape[0]

    @property
    def colors(self) -> torch.Tensor:
        """(N, 3) RGB in (0, 1)."""
        return torch.sigmoid(self.color_logits)

    @property
    def opacities(self) -> torch.Tensor:
        """(N,) in (0, 1)."""
        return torch.sigmoid(self.opacity_logits)

    def resize_like(self, state: dict[str, torch.Tensor]) -> None:
        """Reshape parameters to match a saved state dict (checkpoints hold any N)."""
        for name in PARAM_NAMES:
            setattr(self, name, nn.Parameter(torch.empty_like(state[name])))


def _knn_log_scales(points: torch.Tensor, floor: float) -> torch.Tensor:
    """3DGS-style init: isotropic std = mean distance to the 3 nearest neighbours."""
    from scipy.spatial import cKDTree

    pts = points.numpy()
    k = min(4, len(pts))
    d, _ = cKDTree(pts).query(pts, k=k)
    mean = np.maximum(d[:, 1:].mean(axis=1) if k > 1 else np.full(len(pts), floor), floor)
    return torch.from_numpy(np.log(mean)).float()[:, None].repeat(1, 3)


def init_from_bounds(lo, hi, n: int, seed: int, opacity: float = 0.1) -> CanonicalGaussians:
    """n Gaussians uniform in the box [lo, hi] (metres), grey-ish random colours."""
    g = torch.Generator().manual_seed(seed)
    lo_t, hi_t = torch.as_tensor(lo, dtype=torch.float32), torch.as_tensor(hi, dtype=torch.float32)
    means = lo_t + (hi_t - lo_t) * torch.rand(n, 3, generator=g)
    colors = 0.3 + 0.4 * torch.rand(n, 3, generator=g)
    floor = 1e-3 * float((hi_t - lo_t).norm())
    return CanonicalGaussians(means, _knn_log_scales(means, floor), colors, opacity)


def init_from_points(points: torch.Tensor, colors: torch.Tensor, n: int, seed: int,
                     opacity: float = 0.1) -> CanonicalGaussians:
    """Subsample (M, 3) back-projected points with (M, 3) colours in [0, 1] to n Gaussians."""
    g = torch.Generator().manual_seed(seed)
    idx = torch.randperm(points.shape[0], generator=g)[:n]
    pts = points[idx].float()
    span = float((pts.max(0).values - pts.min(0).values).norm())
    return CanonicalGaussians(pts, _knn_log_scales(pts, 1e-4 * span), colors[idx], opacity)
