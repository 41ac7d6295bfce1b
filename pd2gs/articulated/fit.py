"""Fit an articulated Gaussian model end to end: geometry, appearance, ownership and joints together.

Every step renders one training view of one state with the model posed in that state and takes an Adam
step on: the 3DGS photometric loss ``(1 - l) L1 + l (1 - SSIM)``, plus ``silhouette`` x L1 between the
rendered alpha and the view's object mask where one is given, plus ``depth`` x L1 on the depth of pixels
with a known depth (off by default: PD²GS is RGB-only). The ownership softmax temperature is annealed
geometrically from ``temperature_start`` to ``temperature_end``; at the end the model is made hard.

Gauge: canonical geometry and joint values trade off (moving the canonical body and shifting every value
gives the same renders), so the values of ``ref_state`` are held at their initial values (0 when the
canonical frame is that state's pose, as :mod:`pd2gs.discovery.initialise` builds it).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import torch

from pd2gs.data import Frame
from pd2gs.losses import photometric_loss

from .model import ArticulatedGaussians
from .ownership import reassign


@dataclass
class FitConfig:
    """Settings of :func:`fit_articulated`. Learning rates are Adam step sizes: metres (means, pivots),
    radians or metres (values), unitless (axes stored unnormalised, logits)."""

    iters: int = 900
    lr_means: float = 1e-4
    lr_quats: float = 2e-3
    lr_scales: float = 5e-3
    lr_colors: float = 1e-2
    lr_opacity: float = 2e-2
    lr_ownership: float = 0.2
    lr_axes: float = 5e-3
    lr_pivots: float = 2e-3
    lr_values: float = 5e-3
    temperature_start: float = 1.0
    temperature_end: float = 0.5
    lambda_dssim: float = 0.2
    silhouette: float = 0.5
    depth: float = 0.0
    ref_state: int | None = 0
    background: tuple[float, float, float] = (1.0, 1.0, 1.0)
    backend: str = "cpu"
    harden: bool = True
    seed: int = 0
    # discrete colour-consistency re-assignment of ownership (.ownership.reassign) every this many steps
    # (0 = off), not in the last ``reassign_every`` steps; ``reassign_margin`` mean RGB error
    reassign_every: int = 100
    reassign_margin: float = 0.02
    # ... judged on at most ``reassign_views`` train views, counting a view only where the posed centre is
    # not behind the rendered surface by more than ``reassign_depth_tol`` x the extent (None: no depth test)
    reassign_views: int | None = 64
    reassign_depth_tol: float | None = 0.02
    # over the second half of the steps every learning rate decays geometrically to this fraction of its
    # value (single-view Adam steps jitter the joints around their optimum at a constant rate; 1.0 = constant)
    lr_final: float = 0.1
    # the first this many steps hold the geometry (means, rotations, scales) still, so the joints and
    # ownership, not a deformed canonical shape, have to explain the motion
    joint_warmup: int = 0
    # the first this many steps hold ownership (no ownership gradient, no re-assignment), so the joints are fitted
    # to the bodies as they start before any Gaussian may change body (docs/pd2gs-experiments.md, 35th entry)
    ownership_warmup: int = 0


@dataclass
class FitResult:
    """``losses`` per step; ``seconds`` wall time of the loop; ``iters`` steps run; ``reassigned`` Gaussians
    moved by each ownership re-assignment."""

    losses: list[float] = field(default_factory=list)
    reassigned: list[int] = field(default_factory=list)
    seconds: float = 0.0
    iters: int = 0


OWNERSHIP_GROUP = 5  # index of the ownership logits in :func:`param_groups`


def param_groups(model: ArticulatedGaussians, cfg: FitConfig) -> list[dict]:
    """Adam parameter groups with the config's learning rates."""
    g = model.gaussians
    return [{"params": [g.means], "lr": cfg.lr_means}, {"params": [g.quats], "lr": cfg.lr_quats},
            {"params": [g.log_scales], "lr": cfg.lr_scales}, {"params": [g.color_logits], "lr": cfg.lr_colors},
            {"params": [g.opacity_logits], "lr": cfg.lr_opacity},
            {"params": [model.ownership_logits], "lr": cfg.lr_ownership},
            {"params": [model.axes], "lr": cfg.lr_axes}, {"params": [model.pivots], "lr": cfg.lr_pivots},
            {"params": [model.values], "lr": cfg.lr_values}]


def temperature_at(cfg: FitConfig, step: int) -> float:
    """Geometric anneal from ``temperature_start`` (step 0) to ``temperature_end`` (last step)."""
    f = step / max(1, cfg.iters - 1)
    return cfg.temperature_start * (cfg.temperature_end / cfg.temperature_start) ** f


def view_loss(model: ArticulatedGaussians, frame: Frame, mask: torch.Tensor | None, cfg: FitConfig,
              background: torch.Tensor) -> torch.Tensor:
    """The loss of one view: photometric + silhouette (if ``mask``) + depth (if ``cfg.depth`` > 0)."""
    w, h = frame.size
    out = model.render(frame.state, frame.K, frame.w2c, w, h, background=background, backend=cfg.backend)
    loss = photometric_loss(out.rgb, frame.rgb, cfg.lambda_dssim)
    if mask is not None and cfg.silhouette > 0:
        loss = loss + cfg.silhouette * (out.alpha - mask).abs().mean()
    if cfg.depth > 0 and frame.depth is not None:
        known = frame.depth > 0
        if bool(known.any()):
            loss = loss + cfg.depth * (out.depth[known] - frame.depth[known]).abs().mean()
    return loss


def fit_articulated(model: ArticulatedGaussians, frames: list[Frame], masks: list[torch.Tensor | None] | None = None,
                    cfg: FitConfig | None = None) -> FitResult:
    """Optimise ``model`` in place on the ``train`` frames of every state (``frame.state`` indexes the
    model's states). ``masks``: per frame an (H, W) object mask in [0, 1] or None (parallel to ``frames``)."""
    cfg = cfg or FitConfig()
    if masks is not None and len(masks) != len(frames):
        raise ValueError(f"masks: {len(masks)} masks for {len(frames)} frames")
    train = [i for i, f in enumerate(frames) if f.split == "train"]
    if not train:
        raise ValueError("frames: no frame has split 'train'")
    bad = sorted({frames[i].state for i in train if not 0 <= frames[i].state < model.num_states})
    if bad:
        raise ValueError(f"frames: state index {bad[0]} outside the model's {model.num_states} states")
    if cfg.ref_state is not None and not 0 <= cfg.ref_state < model.num_states:
        raise ValueError(f"ref_state: {cfg.ref_state} is not one of the model's {model.num_states} states")
    model.hard = False
    opt = torch.optim.Adam(param_groups(model, cfg), eps=1e-15, fused=True)  # fused: one kernel per step on CPU too
    base_lrs = [g["lr"] for g in opt.param_groups]
    rng = np.random.default_rng(cfg.seed)
    bg = torch.tensor(cfg.background)
    res = FitResult()
    order: list[int] = []
    t0 = time.perf_counter()
    for step in range(cfg.iters):
        if not order:
            order = list(rng.permutation(train))
        i = order.pop()
        model.temperature = temperature_at(cfg, step)
        half = cfg.iters // 2
        decay = cfg.lr_final ** (max(0, step - half) / max(1, cfg.iters - 1 - half))
        for k, (group, lr) in enumerate(zip(opt.param_groups, base_lrs)):
            held = (k < 3 and step < cfg.joint_warmup) or (k == OWNERSHIP_GROUP and step < cfg.ownership_warmup)
            group["lr"] = 0.0 if held else lr * decay
        opt.zero_grad(set_to_none=True)
        loss = view_loss(model, frames[i], None if masks is None else masks[i], cfg, bg)
        loss.backward()
        if cfg.ref_state is not None and model.values.grad is not None:
            model.values.grad[cfg.ref_state] = 0
        opt.step()
        res.losses.append(float(loss.detach()))
        every = cfg.reassign_every
        if every and (step + 1) % every == 0 and step + 1 + every <= cfg.iters and step >= cfg.ownership_warmup:
            res.reassigned.append(reassign(model, frames, masks, cfg.reassign_margin, max_views=cfg.reassign_views,
                                           depth_tol=cfg.reassign_depth_tol, background=cfg.background,
                                           backend=cfg.backend))
    res.seconds = time.perf_counter() - t0
    res.iters = cfg.iters
    if cfg.harden:
        model.harden()
    return res


@torch.no_grad()
def view_errors(model: ArticulatedGaussians, frames: list[Frame], split: str = "test", background=(1.0, 1.0, 1.0),
                backend: str = "cpu", masks: list[torch.Tensor | None] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per ``split`` frame (one render each) the mean L1 colour error of the model's render and the mean
    |rendered alpha - mask| (0 where ``masks``, parallel to ``frames``, gives none) -> two (V,) arrays."""
    if masks is not None and len(masks) != len(frames):
        raise ValueError(f"masks: {len(masks)} masks for {len(frames)} frames")
    bg = torch.tensor(background)
    l1, sil = [], []
    for i, f in enumerate(frames):
        if f.split == split:
            out = model.render(f.state, f.K, f.w2c, *f.size, background=bg, backend=backend)
            l1.append(float((out.rgb - f.rgb).abs().mean()))
            m = masks[i] if masks is not None else None
            sil.append(0.0 if m is None else float((out.alpha - m).abs().mean()))
    return np.asarray(l1, dtype=np.float64), np.asarray(sil, dtype=np.float64)


def held_out_loss(l1: np.ndarray, sil: np.ndarray, silhouette: float) -> float:
    """Mean over views of L1 + ``silhouette`` x silhouette error (:func:`view_errors`'s arrays; nan if none)."""
    return float(np.mean(l1 + silhouette * sil)) if len(l1) else float("nan")


def evaluate_views(model: ArticulatedGaussians, frames: list[Frame], split: str = "test",
                   background=(1.0, 1.0, 1.0), backend: str = "cpu", masks: list[torch.Tensor | None] | None = None,
                   silhouette: float = 0.0) -> float:
    """Mean over the ``split`` frames of the model's held-out loss (nan if none): the L1 colour error of its
    render, plus ``silhouette`` x the mean |rendered alpha - mask| where ``masks`` (parallel to ``frames``)
    gives the view's object mask. With ``silhouette`` at the fit's weight this is the fit's objective less
    its SSIM term, so the models that selection compares are judged by what the fit optimised: an RGB-only
    score cannot see a white door against a white background (measured on refrigerator-0000, docs/
    pd2gs-parts.md)."""
    return held_out_loss(*view_errors(model, frames, split, background, backend, masks), silhouette)
