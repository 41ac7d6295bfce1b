"""Photometric losses: SSIM equals the textbook conv2d formulation, values and gradients."""
from __future__ import annotations

import torch
import torch.nn.functional as F

from pd2gs.losses import photometric_loss, psnr, ssim


def _ssim_conv(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """3DGS-style SSIM with explicit 11x11 Gaussian conv2d (sigma 1.5, zero padding)."""
    x = torch.arange(11, dtype=torch.float32) - 5
    w = torch.exp(-x ** 2 / (2 * 1.5 ** 2))
    w = (w / w.sum()).to(a.dtype)  # float32 weights, as pd2gs.losses
    win = (w[:, None] * w[None, :])[None, None].repeat(3, 1, 1, 1)

    def blur(t):
        return F.conv2d(t, win, padding=5, groups=3)

    x1, y1 = a.permute(2, 0, 1)[None], b.permute(2, 0, 1)[None]
    mx, my = blur(x1), blur(y1)
    sxx, syy, sxy = blur(x1 * x1) - mx ** 2, blur(y1 * y1) - my ** 2, blur(x1 * y1) - mx * my
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    return ((2 * mx * my + c1) * (2 * sxy + c2) / ((mx ** 2 + my ** 2 + c1) * (sxx + syy + c2))).mean()


def test_ssim_matches_conv2d_formulation_and_gradient():
    g = torch.Generator().manual_seed(0)
    gt = torch.rand(37, 50, 3, generator=g, dtype=torch.float64)
    pred = (gt + 0.2 * torch.randn(37, 50, 3, generator=g, dtype=torch.float64)).requires_grad_()
    s_fast, s_ref = ssim(pred, gt), _ssim_conv(pred, gt)
    s_fast_v, s_ref_v = float(s_fast.detach()), float(s_ref.detach())
    assert 0.0 < s_ref_v < 0.99
    assert abs(s_fast_v - s_ref_v) < 1e-12
    g_fast, = torch.autograd.grad(s_fast, pred)
    g_ref, = torch.autograd.grad(s_ref, pred)
    assert float((g_fast - g_ref).abs().max() / g_ref.abs().max()) < 1e-10


def test_ssim_of_identical_images_is_one_and_loss_zero():
    img = torch.rand(32, 32, 3, generator=torch.Generator().manual_seed(1))
    assert abs(float(ssim(img, img)) - 1.0) < 1e-5
    assert float(photometric_loss(img, img)) < 1e-5
    assert psnr(img, img) == float("inf")
