"""Evaluation of a trained field on states it never saw, by latent interpolation.

For an unseen state u, the latent is searched on the segment between consecutive training states
(in the run's state order): alpha = (1 - t) alpha_k + t alpha_{k+1}, t on a grid. The (k, t) with
the best PSNR on the even-numbered views of u is kept and PSNR is reported on the odd-numbered
views, so the views that pick the latent are not the views that score it.
"""
from __future__ import annotations

import numpy as np
import torch

from pd2gs.data import Frame
from pd2gs.deform import DeformableField
from pd2gs.losses import psnr
from pd2gs.train import render_frame


@torch.no_grad()
def _mean_psnr(fld, latent, frames, background, backend) -> float:
    return float(np.mean([psnr(render_frame(fld, latent, f, background, backend).rgb.clamp(0, 1), f.rgb)
                          for f in frames]))


@torch.no_grad()
def eval_unseen(fld: DeformableField, frames: list[Frame], background, backend: str = "cpu",
                steps: int = 11) -> dict:
    """frames: views of ONE unseen state (>= 2). Returns {segment, t, fit_psnr, psnr, views}."""
    fit, score = frames[0::2], frames[1::2]
    if not score:
        raise ValueError("need at least 2 views of the unseen state")
    k_states = fld.latents.shape[0]
    best = None
    for k in range(max(1, k_states - 1)):
        k1 = min(k + 1, k_states - 1)
        for t in np.linspace(0.0, 1.0, steps):
            p = _mean_psnr(fld, fld.interpolate(k, k1, float(t)), fit, background, backend)
            if best is None or p > best[0]:
                best = (p, k, k1, float(t))
    p_fit, k, k1, t = best
    p = _mean_psnr(fld, fld.interpolate(k, k1, t), score, background, backend)
    return {"segment": [k, k1], "t": t, "fit_psnr": p_fit, "psnr": p,
            "views": {"fit": len(fit), "scored": len(score)}}
