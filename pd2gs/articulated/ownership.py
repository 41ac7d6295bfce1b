"""Discrete ownership re-assignment by colour consistency (a complement to the soft ownership gradient).

Measured on the lid scene (docs/pd2gs-articulated.md): the gradient of the soft ownership cannot move a
Gaussian to the right body when its bodies' poses put it far apart (a lid Gaussian owned by the base
sits on the base while the lid's image is 20 cm away: no pixel links the two). Here every Gaussian is
tried on every body: posed with that body in each training view of each state, its centre is projected
and the image colour there compared with its own colour (outside the object's mask counts as the worst
error). A view counts for a hypothesis only where the posed centre is not hidden behind the current
model's rendered surface (deeper than its expected depth by more than ``depth_tol`` x the object's
extent): a Gaussian inside a closed box, or the inside of a drawer, is evidence for no body. The body with
the lowest median error over the views that see it wins when it beats the current owner by ``margin``;
its logits are then reset to +/- confidence/2. A Gaussian that no view sees under its owner moves only to a
body under which it matches the images within ``margin``; one that no view sees at all keeps its owner.
"""
from __future__ import annotations

import numpy as np
import torch

from pd2gs.data import Frame

from .model import ArticulatedGaussians


def view_subset(frames: list[Frame], split: str, max_views: int | None) -> list[int]:
    """Indices of the ``split`` frames, at most ``max_views`` of them spread evenly over each state's."""
    idx = [i for i, f in enumerate(frames) if f.split == split]
    if max_views is None or len(idx) <= max_views:
        return idx
    states = sorted({frames[i].state for i in idx})
    per = max(1, max_views // len(states))
    out = []
    for s in states:
        own = [i for i in idx if frames[i].state == s]
        out += [own[k] for k in np.unique(np.linspace(0, len(own) - 1, min(per, len(own))).round().astype(int))]
    return out


@torch.no_grad()
def colour_costs(model: ArticulatedGaussians, frames: list[Frame], masks=None, split: str = "train",
                 max_views: int | None = None, depth_tol: float | None = 0.02,
                 background=(1.0, 1.0, 1.0), backend: str = "cpu") -> torch.Tensor:
    """(N, K+1) median over the ``split`` views (at most ``max_views``, :func:`view_subset`) of the mean
    absolute RGB difference between each Gaussian's colour and the image colour at its centre's pixel when
    posed with body b; 1 outside the mask; NaN where no view sees the centre inside the image, or (with
    ``depth_tol``, a fraction of the canonical extent) where it lies behind the current model's rendered
    surface (its expected depth where the alpha reaches 0.5) in every view."""
    g = model.gaussians
    col = g.colors.detach()
    tol = None
    if depth_tol is not None:
        tol = depth_tol * float(torch.linalg.norm(g.means.detach().amax(0) - g.means.detach().amin(0)))
    bg = torch.tensor(background)
    per_view = []
    for i in view_subset(frames, split, max_views):
        f = frames[i]
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
        if tol is not None:
            out = model.render(f.state, f.K, f.w2c, w, h, background=bg, backend=backend)
            surface = torch.where(out.alpha >= 0.5, out.depth, torch.full_like(out.depth, float("inf")))
            ok = ok & (z <= surface.to(z)[yc, xc] + tol)
        per_view.append(torch.where(ok, err, torch.full_like(err, float("nan"))))
    if not per_view:
        raise ValueError(f"frames: no frame has split {split!r}")
    return torch.nanmedian(torch.stack(per_view), dim=0).values


@torch.no_grad()
def reassign(model: ArticulatedGaussians, frames: list[Frame], masks=None, margin: float = 0.05,
             confidence: float = 4.0, max_views: int | None = 64, depth_tol: float | None = 0.02,
             background=(1.0, 1.0, 1.0), backend: str = "cpu") -> int:
    """Give each Gaussian to its most colour-consistent body where that beats its current owner by
    ``margin`` (mean RGB error); -> the number of Gaussians moved. See :func:`colour_costs`."""
    cost = colour_costs(model, frames, masks, "train", max_views, depth_tol, background, backend)
    n = torch.arange(cost.shape[0])
    # no view sees it under its owner: it moves only where another body matches the images within margin
    cur_cost = torch.nan_to_num(cost[n, model.labels()], nan=2 * margin)
    return move_to_cheapest(model, torch.nan_to_num(cost, nan=float("inf")), margin, confidence, cur_cost)


@torch.no_grad()
def move_to_cheapest(model: ArticulatedGaussians, cost: torch.Tensor, margin: float, confidence: float = 4.0,
                     current: torch.Tensor | None = None) -> int:
    """Give each Gaussian to the body of least ``cost`` (N, K+1) where that beats ``current`` (N,) (default:
    its owner's cost) by ``margin``; its logits are reset to +/- confidence / 2. -> the number moved."""
    n = torch.arange(cost.shape[0])
    cur = model.labels()
    if current is None:
        current = cost[n, cur]
    best = cost.argmin(1)
    move = (best != cur) & (current - cost[n, best] > margin)
    if bool(move.any()):
        logits = model.ownership_logits
        logits[move] = -confidence / 2
        logits[move, best[move]] = confidence / 2
    return int(move.sum())
