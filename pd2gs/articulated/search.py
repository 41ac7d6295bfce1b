"""Coarse joint search: each movable body's joint chosen among rendered hypotheses before the gradient fit.

A gradient fit of a joint started far from the truth stalls: a Kabsch estimate on a stage-1 cluster that
mixes two parts, or on a field that moved only some of a part's Gaussians, can point a hinge 30° off or
call a slide a hinge, and the photometric loss has no slope that leads back. This step renders, for one
body at a time (the others held at their current joints, ownership hard), a grid of hypotheses and keeps
the one with the lowest mean L1 colour error on a few training views of every state:

* axes: the current axis and the three principal directions of the body's canonical centres;
* revolute pivots: the current pivot, the body's centroid and the four corners of its extent in the
  plane orthogonal to the axis (hinges sit at part edges);
* values linear in the state's position between the reference state (value 0) and the last one
  (``ramp``), the far value on a grid: angles in [-pi, pi), slides in [-1.5, 1.5] x the body's extent;
* the current joint itself, so the search never returns something that renders worse.

Forward renders only; the gradient fit (:mod:`.fit`) refines every value afterwards.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from pd2gs.data import Frame

from .model import ArticulatedGaussians
from .ownership import view_subset


@dataclass
class SearchConfig:
    """Grid sizes of :func:`search_joints`; ``views_per_state`` training views per state are rendered per
    hypothesis; ``ramp`` (S,) the far value's share in each state (None: linear from the ``ref`` state);
    hypotheses are rendered with at most ``max_gaussians`` of the model's Gaussians (the most opaque: a
    render costs about the same at any image size here, so the Gaussian count sets the search's time)."""

    angle_steps: int = 12
    slide_steps: int = 13
    views_per_state: int = 1
    max_gaussians: int = 4000
    ramp: list[float] | None = None
    # a found joint replaces the current one only when it also lowers the mean L1 on ``check_views``
    # held-out views per state by more than ``min_gain_rel`` x the current held-out L1 (the selection
    # penalty's rule: a structural change must pay for itself on views the search did not choose on)
    check_views: int = 2
    min_gain_rel: float = 0.02
    background: tuple[float, float, float] = (1.0, 1.0, 1.0)
    backend: str = "cpu"


@dataclass
class SearchResult:
    """Per body: the chosen hypothesis and the current joint's and the chosen one's losses."""

    chosen: dict[int, dict] = field(default_factory=dict)


def _ramp(num_states: int, ref: int) -> np.ndarray:
    """(S,) 0 at ``ref``, 1 at the state farthest from it, linear in the state index."""
    idx = np.arange(num_states, dtype=np.float64) - ref
    far = np.abs(idx).max() or 1.0
    return idx / far


@torch.no_grad()
def _loss(model: ArticulatedGaussians, views: list[Frame], bg: torch.Tensor, backend: str) -> float:
    err = 0.0
    for f in views:
        out = model.render(f.state, f.K, f.w2c, *f.size, background=bg, backend=backend)
        err += float((out.rgb - f.rgb).abs().mean())
    return err / max(1, len(views))


def hypotheses(model: ArticulatedGaussians, b: int, ramp: np.ndarray, cfg: SearchConfig
               ) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """Body b's joint hypotheses -> [(type, unit axis (3,), pivot (3,), values (S,))] (see module doc)."""
    j = b - 1
    P = model.gaussians.means.detach()[model.labels() == b].double().numpy()
    if len(P) < 3:
        return []
    centre = P.mean(0)
    extent = float(np.linalg.norm(np.ptp(P, axis=0))) or 1e-3
    axes: list[np.ndarray] = []
    for a in [model.unit_axes[j].detach().double().numpy()] + list(np.linalg.svd(P - centre, full_matrices=False)[2]):
        a = a / (np.linalg.norm(a) + 1e-12)
        if all(abs(float(a @ c)) < 0.985 for c in axes):  # drop near-duplicates (< 10 deg apart)
            axes.append(a)
    out = []
    angles = np.linspace(-math.pi, math.pi, cfg.angle_steps, endpoint=False)
    slides = np.linspace(-1.5, 1.5, cfg.slide_steps) * extent
    for a in axes:
        e = np.linalg.svd(np.eye(3) - np.outer(a, a))[0][:, :2]  # basis of the plane orthogonal to a
        q = (P - centre) @ e
        lo, hi = q.min(0), q.max(0)
        pivots = [model.pivots[j].detach().double().numpy(), centre]
        pivots += [centre + e @ np.array([x, y]) for x in (lo[0], hi[0]) for y in (lo[1], hi[1])]
        for v in angles:
            if abs(v) < 1e-9:
                continue
            out += [("revolute", a, p, v * ramp) for p in pivots]
        for v in slides:
            if abs(v) > 1e-9:
                out.append(("prismatic", a, centre, v * ramp))
    return out


def _set_joint(model: ArticulatedGaussians, j: int, t: str, axis, pivot, values) -> None:
    model.joint_types[j] = t
    model.axes.data[j] = torch.as_tensor(np.asarray(axis), dtype=model.axes.dtype)
    model.pivots.data[j] = torch.as_tensor(np.asarray(pivot), dtype=model.pivots.dtype)
    model.values.data[:, j] = torch.as_tensor(np.asarray(values), dtype=model.values.dtype)


@torch.no_grad()
def search_joints(model: ArticulatedGaussians, frames: list[Frame], ref: int = 0,
                  cfg: SearchConfig | None = None) -> SearchResult:
    """Replace each movable body's joint (in place, bodies in order) by the best-rendering hypothesis on the
    training views, where it also renders the held-out views better (see :class:`SearchConfig`; without
    held-out views the training views' choice stands)."""
    cfg = cfg or SearchConfig()
    n_states = len({f.state for f in frames})
    views = [frames[i] for i in view_subset(frames, "train", cfg.views_per_state * n_states)]
    if not views:
        raise ValueError("frames: the joint search needs training views (split 'train')")
    check = [frames[i] for i in view_subset(frames, "test", cfg.check_views * n_states)]
    ramp = np.asarray(cfg.ramp, dtype=np.float64) if cfg.ramp is not None else _ramp(model.num_states, ref)
    bg = torch.tensor(cfg.background)
    full, model = model, subsample(model, cfg.max_gaussians)
    model.harden()
    res = SearchResult()
    for b in range(1, model.num_bodies):
        j = b - 1
        current = (model.joint_types[j], model.axes[j].clone(), model.pivots[j].clone(), model.values[:, j].clone())
        best_loss = start_loss = _loss(model, views, bg, cfg.backend)
        best = None
        for t, a, p, v in hypotheses(model, b, ramp, cfg):
            _set_joint(model, j, t, a, p, v)
            loss = _loss(model, views, bg, cfg.backend)
            if loss < best_loss:
                best_loss, best = loss, (t, a, p, v)
        info = {"loss_before": start_loss, "loss_after": best_loss}
        if best is not None and check:
            _set_joint(model, j, *current)
            held_before = _loss(model, check, bg, cfg.backend)
            _set_joint(model, j, *best)
            held_after = _loss(model, check, bg, cfg.backend)
            info.update(held_out_before=held_before, held_out_after=held_after)
            if held_after >= held_before * (1.0 - cfg.min_gain_rel):
                best = None
        _set_joint(model, j, *(best if best is not None else current))
        if best is not None:
            _set_joint(full, j, *best)
        res.chosen[b] = {"type": model.joint_types[j], **info, "changed": best is not None}
    return res


def subsample(model: ArticulatedGaussians, n: int) -> ArticulatedGaussians:
    """A copy of ``model`` with its ``n`` most opaque Gaussians (all when it has no more), same joints and
    hard labels."""
    from .model import canonical_gaussians

    g = model.gaussians
    keep = torch.argsort(g.opacities.detach().reshape(-1), descending=True)[:n]
    sub = canonical_gaussians(g.means.detach()[keep], g.quats.detach()[keep], torch.exp(g.log_scales.detach()[keep]),
                              g.colors.detach()[keep], g.opacities.detach().reshape(-1)[keep])
    return ArticulatedGaussians(sub, model.parent, list(model.joint_types), model.axes.detach(),
                                model.pivots.detach(), model.values.detach(), model.labels()[keep])
