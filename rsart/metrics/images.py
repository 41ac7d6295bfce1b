"""Image metrics: PSNR, SSIM (novel views / unseen states) and part-mask IoU / accuracy / F1.

PSNR and SSIM follow the 3DGS code that ArtGS and PD²GS report with: images as floats in [0, 1],
PSNR = ``10·log10(1/MSE)`` over all pixels and channels; SSIM with an 11×11 Gaussian window
(σ = 1.5), C1 = 0.01², C2 = 0.03², zero padding ("same" size), averaged over pixels and channels.
Written with scipy.ndimage because neither torch-free skimage nor the 3DGS torch function is in our
stack; the zero-padded 11-tap window reproduces the 3DGS ``F.conv2d(..., padding=5)`` exactly.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import correlate1d

SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
PSNR_MAX = 100.0


def to_float01(img: np.ndarray) -> np.ndarray:
    """(H, W[, C]) uint8/uint16/float image -> float64 in [0, 1] with a channel axis (H, W, C)."""
    a = np.asarray(img)
    if a.dtype == np.uint8:
        a = a.astype(np.float64) / 255.0
    elif a.dtype == np.uint16:
        a = a.astype(np.float64) / 65535.0
    else:
        a = a.astype(np.float64)
    return a[..., None] if a.ndim == 2 else a


def psnr(pred: np.ndarray, gt: np.ndarray) -> float:
    """PSNR (dB) of two same-shape images, capped at ``PSNR_MAX`` (identical images: 100 dB, never inf)."""
    p, g = to_float01(pred), to_float01(gt)
    if p.shape != g.shape:
        raise ValueError(f"image shapes differ: {p.shape} vs {g.shape}")
    mse = float(np.mean((p - g) ** 2))
    return min(PSNR_MAX, 10.0 * math.log10(1.0 / mse)) if mse > 0 else PSNR_MAX


def _gauss_window(size: int = SSIM_WINDOW, sigma: float = SSIM_SIGMA) -> np.ndarray:
    x = np.arange(size) - size // 2
    w = np.exp(-(x ** 2) / (2 * sigma ** 2))
    return w / w.sum()


def _blur(a: np.ndarray, w: np.ndarray) -> np.ndarray:
    a = correlate1d(a, w, axis=0, mode="constant", cval=0.0)
    return correlate1d(a, w, axis=1, mode="constant", cval=0.0)


def ssim(pred: np.ndarray, gt: np.ndarray) -> float:
    """Mean SSIM of two same-shape images (see module docstring for the exact window and constants)."""
    p, g = to_float01(pred), to_float01(gt)
    if p.shape != g.shape:
        raise ValueError(f"image shapes differ: {p.shape} vs {g.shape}")
    w = _gauss_window()
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    vals = []
    for c in range(p.shape[2]):
        x, y = p[..., c], g[..., c]
        mx, my = _blur(x, w), _blur(y, w)
        sxx = _blur(x * x, w) - mx * mx
        syy = _blur(y * y, w) - my * my
        sxy = _blur(x * y, w) - mx * my
        m = ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx * mx + my * my + c1) * (sxx + syy + c2))
        vals.append(m)
    return float(np.mean(vals))


def mask_scores(pred: np.ndarray, gt: np.ndarray, pred_to_true: dict[int, int] | None = None) -> dict:
    """Part-mask scores of a predicted (H, W) label image against the true one (0 = background, k = part k−1).

    ``pred_to_true`` maps predicted labels to true labels (from the part matching); predicted labels not in
    it count as wrong everywhere (label −1). Returns ``accuracy`` (pixel accuracy over the whole image,
    background included), ``iou`` and ``f1`` per true part label present in ``gt`` (dict label -> value),
    and their means ``miou`` / ``mf1`` over those labels.
    """
    p = np.asarray(pred).astype(np.int64)
    g = np.asarray(gt).astype(np.int64)
    if p.shape != g.shape:
        raise ValueError(f"mask shapes differ: {p.shape} vs {g.shape}")
    if pred_to_true is not None:
        lut = {0: 0, **{int(k): int(v) for k, v in pred_to_true.items()}}
        mapped = np.full_like(p, -1)
        for k, v in lut.items():
            mapped[p == k] = v
        p = mapped
    labels = [int(v) for v in np.unique(g) if v != 0]
    iou, f1 = {}, {}
    for k in labels:
        P, G = p == k, g == k
        inter = float(np.logical_and(P, G).sum())
        union = float(np.logical_or(P, G).sum())
        iou[k] = inter / union
        f1[k] = 2 * inter / (float(P.sum()) + float(G.sum()))
    return {"accuracy": float(np.mean(p == g)), "iou": iou, "f1": f1,
            "miou": float(np.mean(list(iou.values()))) if iou else None,
            "mf1": float(np.mean(list(f1.values()))) if f1 else None}
