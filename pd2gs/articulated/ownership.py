"""Discrete ownership re-assignment by colour consistency (a complement to the soft ownership gradient).

Measured on the lid scene (docs/pd2gs-articulated.md): the gradient of the soft ownership cannot move a
Gaussian to the right body when its bodies' poses put it far apart (a lid Gaussian owned by the base
sits on the base while the lid's image is 20 cm away: no pixel links the two). Here every Gaussian is
tried on every body: posed with that body in each training view of each state, its centre is projected
and the image colour there compared with its own colour (outside the object's mask counts as the worst
error). The body with the lowest median error over the views wins when it beats the current owner by
``margin``; its logits are then reset to +/- confidence/2.
"""
from __future__ import annotations

import torch

from pd2gs.data import Frame

from .model import ArticulatedGaussians


@torch.no_grad()
def colour_costs(model: ArticulatedGaussians, frames: list[Frame], masks=None, split: str = "train") -> torch.Tensor:
    """(N, K+1) median over the ``split`` views of the mean absolute RGB difference between each Gaussian's
    colour and the image colour at its centre's pixel when posed with body b; 1 outside the mask, NaN
    where no view sees the centre inside the image."""
    g = model.gaussians
    col = g.colors.detach()
    per_view = []
    for i, f in enumerate(frames):
        if f.split != split:
            continue
        bp = model.body_poses(f.state)
        moved = torch.einsum("bij,nj->nbi", bp.R.detach(), g.means.detach()) + bp.t.detach()[None]  # (N, B, 3)
        w2c = f.w2c.to(moved)
        cam = moved @ w2c[:3, :3].T + w2c[:3, 3]
        z = cam[..., 2]
        uv = cam[..., :2] / z.clamp_min(1e-6)[..., None] @ f.K[:2, :2].to(moved).T + f.K[:2, 2].to(moved)
        w, h = f.size
        x, y = uv[..., 0].round().long(), uv[..., 1].round().long()
        ok = (z > 1e-6) & (x >= 0) & (x < w) & (y >= 0) & (y < h)
        xc, yc = x.clamp(0, w - 1), y.clamp(0, h - 1)
        err = (f.rgb[yc, xc].to(col) - col[:, None]).abs().mean(-1)
        if masks is not None and masks[i] is not None:
            err = torch.where(masks[i][yc, xc] > 0.5, err, torch.ones_like(err))
        per_view.append(torch.where(ok, err, torch.full_like(err, float("nan"))))
    if not per_view:
        raise ValueError(f"frames: no frame has split {split!r}")
    return torch.nanmedian(torch.stack(per_view), dim=0).values


@torch.no_grad()
def reassign(model: ArticulatedGaussians, frames: list[Frame], masks=None, margin: float = 0.05,
             confidence: float = 4.0) -> int:
    """Give each Gaussian to its most colour-consistent body where that beats its current owner by
    ``margin`` (mean RGB error); -> the number of Gaussians moved."""
    cost = colour_costs(model, frames, masks)
    cost = torch.nan_to_num(cost, nan=2.0)
    cur = model.labels()
    best = cost.argmin(1)
    n = torch.arange(cost.shape[0])
    move = (best != cur) & (cost[n, cur] - cost[n, best] > margin)
    if bool(move.any()):
        logits = model.ownership_logits
        logits[move] = -confidence / 2
        logits[move, best[move]] = confidence / 2
    return int(move.sum())
