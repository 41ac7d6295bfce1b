"""Differentiable 3D Gaussian rasterization: one API, three backends.

``rasterize(...)`` projects Gaussians (``projection.py``, PyTorch autograd; the ``cpu`` backend
uses the same arithmetic as a Numba kernel, ``projection_cpu.py``), bins them
into 16x16 tiles sorted by depth, and composites front to back with the exact 3DGS rules:
alpha = min(0.99, o * exp(-1/2 d^T Sigma'^-1 d)), entries with alpha < 1/255 skipped, a pixel
stops before the Gaussian that would bring its transmittance below 1e-4, and Sigma' carries a
0.3 px^2 low-pass dilation. Backends:

* ``reference``: pure PyTorch, autograd gradients; the ground truth for tests.
* ``cpu``: Numba kernels for projection and compositing, hand-written backward passes,
  per-pixel early termination (default).
* ``gsplat``: gsplat's CUDA rasterizer (optional extra; needs CUDA).

Conventions: see ``projection.py`` (OpenCV camera, integer pixel centres, quaternions (w,x,y,z),
Sigma = R diag(s)^2 R^T with s the per-axis standard deviation in metres).
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from pd2gs.render.projection import Projected, project_gaussians
from rsart.errors import RsartError

BACKENDS = ("cpu", "reference", "gsplat")


class BackendUnavailable(RsartError, RuntimeError):
    """The requested backend cannot run on this machine (message says why and what to use)."""


@dataclass
class RenderOutput:
    """Result of one ``rasterize`` call (H x W image, N Gaussians, L labels).

    rgb: (H, W, 3) colour including the background.
    alpha: (H, W) accumulated opacity 1 - T_final.
    depth: (H, W) expected camera-space depth sum_i w_i z_i / sum_i w_i in metres (0 where
        alpha < 1e-6).
    means2d: (N, 2) projected centres in pixels; call ``means2d.retain_grad()`` before backward
        to read the view-space positional gradient used by densification.
    radii: (N,) int32 screen radius in pixels, 0 = culled.
    label_weights: (H, W, L) or None; label_weights[y, x, l] = sum of compositing weights
        w_i(x) over Gaussians i with label l (no gradient). Sums over l to ``alpha``.
    max_weight: (N,) or None; max over pixels of w_i(x) (no gradient). ``visible`` is
        ``max_weight > 0``.
    """

    rgb: torch.Tensor
    alpha: torch.Tensor
    depth: torch.Tensor
    means2d: torch.Tensor
    radii: torch.Tensor
    label_weights: torch.Tensor | None = None
    max_weight: torch.Tensor | None = None

    @property
    def visible(self) -> torch.Tensor | None:
        """(N,) bool: the Gaussian got a non-zero weight at some pixel (needs max_weight)."""
        return None if self.max_weight is None else self.max_weight > 0


def rasterize(
    means: torch.Tensor,
    quats: torch.Tensor,
    scales: torch.Tensor,
    colors: torch.Tensor,
    opacities: torch.Tensor,
    K: torch.Tensor,
    w2c: torch.Tensor,
    width: int,
    height: int,
    background: torch.Tensor | None = None,
    backend: str = "cpu",
    labels: torch.Tensor | None = None,
    num_labels: int | None = None,
    return_max_weight: bool = False,
) -> RenderOutput:
    """Render N Gaussians into one camera.

    Args:
        means: (N, 3) world positions (m). quats: (N, 4) (w, x, y, z), any norm.
        scales: (N, 3) per-axis standard deviations (m), > 0. colors: (N, 3) RGB in [0, 1].
        opacities: (N,) in [0, 1]. K: (3, 3) intrinsics (px). w2c: (4, 4) world-to-camera.
        background: (3,) RGB or None (black).
        labels: (N,) int in [0, num_labels) to also return per-label weights; num_labels
            defaults to labels.max() + 1.
        return_max_weight: also return per-Gaussian max contribution (visibility).
    All float inputs must share one dtype (float32 or float64); everything stays on CPU except
    for the gsplat backend.
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if labels is not None and num_labels is None:
        num_labels = int(labels.max()) + 1 if labels.numel() else 1
    if backend == "gsplat":
        from pd2gs.render.gsplat_backend import rasterize_gsplat
        return rasterize_gsplat(means, quats, scales, colors, opacities, K, w2c, width, height,
                                background, labels, num_labels or 0, return_max_weight)
    if backend == "cpu":
        from pd2gs.render.projection_cpu import project_gaussians_cpu
        proj = project_gaussians_cpu(means, quats, scales, K, w2c, width, height)
    else:
        proj = project_gaussians(means, quats, scales, K, w2c, width, height)
    features = torch.cat([colors, proj.depths[:, None]], dim=1)
    if backend == "cpu":
        from pd2gs.render.cpu import bin_gaussians_cpu, rasterize_cpu
        offsets, gids = bin_gaussians_cpu(proj.means2d, proj.depths, proj.radii, width, height,
                                          proj.conics, opacities)
        raster = rasterize_cpu
    else:
        from pd2gs.render.binning import bin_gaussians_torch
        from pd2gs.render.reference import rasterize_reference
        offsets, gids = bin_gaussians_torch(proj.means2d, proj.depths, proj.radii, width, height)
        raster = rasterize_reference
    feat, trans, lw, maxw = raster(proj.means2d, proj.conics, opacities, features, offsets, gids,
                                   width, height, labels, num_labels or 0, return_max_weight)
    return _finish(proj, feat, trans, lw, maxw, background)


def _finish(proj: Projected, feat, trans, lw, maxw, background) -> RenderOutput:
    """Add the background and normalise depth."""
    rgb = feat[..., :3]
    if background is not None:
        rgb = rgb + trans[..., None] * background.to(rgb)
    alpha = 1 - trans
    has = alpha > 1e-6
    depth = torch.where(has, feat[..., 3] / torch.where(has, alpha, torch.ones_like(alpha)),
                        torch.zeros_like(alpha))
    return RenderOutput(rgb, alpha, depth, proj.means2d, proj.radii, lw, maxw)
