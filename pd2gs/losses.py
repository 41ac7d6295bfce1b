"""Photometric losses: L1, SSIM (11x11 Gaussian window, sigma 1.5) and PSNR on (H, W, 3) images."""
from __future__ import annotations

import torch
import torch.nn.functional as F

_C1, _C2 = 0.01 ** 2, 0.03 ** 2


def _window(size: int = 11, sigma: float = 1.5) -> torch.Tensor:
    x = torch.arange(size, dtype=torch.float32) - size // 2
    w = torch.exp(-x ** 2 / (2 * sigma ** 2))
    return w / w.sum()


_W = _window()


def _blur(x: torch.Tensor) -> torch.Tensor:
    """Separable Gaussian blur of (C, 1, H, W) with zero padding (as 3DGS's ssim)."""
    w = _W.to(x)
    x = F.conv2d(x, w.view(1, 1, 1, -1), padding=(0, 5))
    return F.conv2d(x, w.view(1, 1, -1, 1), padding=(5, 0))


def ssim(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Mean SSIM of two (H, W, 3) images in [0, 1]."""
    x = a.permute(2, 0, 1)[:, None]
    y = b.permute(2, 0, 1)[:, None]
    mx, my = _blur(x), _blur(y)
    sxx = _blur(x * x) - mx * mx
    syy = _blur(y * y) - my * my
    sxy = _blur(x * y) - mx * my
    num = (2 * mx * my + _C1) * (2 * sxy + _C2)
    den = (mx * mx + my * my + _C1) * (sxx + syy + _C2)
    return (num / den).mean()


def photometric_loss(pred: torch.Tensor, gt: torch.Tensor, lambda_dssim: float = 0.2) -> torch.Tensor:
    """(1 - lambda) L1 + lambda (1 - SSIM), the 3DGS loss (lambda = 0.2)."""
    return (1 - lambda_dssim) * (pred - gt).abs().mean() + lambda_dssim * (1 - ssim(pred, gt))


def psnr(pred: torch.Tensor, gt: torch.Tensor) -> float:
    """PSNR in dB for images in [0, 1]."""
    mse = float(((pred.detach() - gt) ** 2).mean())
    return float("inf") if mse == 0 else -10.0 * torch.log10(torch.tensor(mse)).item()
