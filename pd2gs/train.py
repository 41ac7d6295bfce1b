"""PD²GS training: jointly optimise canonical Gaussians, the deformation MLP and K state latents.

One iteration = pick a training view (state k), deform the canonical field with alpha_k,
rasterize, loss (1 - 0.2) L1 + 0.2 (1 - SSIM), backward, Adam step, density control.
Deterministic given ``seed`` (fixed thread count, deterministic kernels, seeded sampling).
"""
from __future__ import annotations

import json
import math
import random
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from pd2gs.config import TrainConfig  # noqa: F401  (its home is pd2gs/config.py; imported from here too)
from pd2gs.data import Frame, backproject_frames, camera_bounds, object_bounds
from pd2gs.deform import DeformableField, DeformedGaussians
from pd2gs.densify import DensifyStats, densify_and_prune, reset_opacity
from pd2gs.gaussians import init_from_bounds, init_from_points
from pd2gs.losses import photometric_loss, psnr
from pd2gs.render import rasterize
from pd2gs.rigidity import NeighbourGraph, isometry_loss, knn_graph
from rsart.io import write_json


def estimate_background(frames: list[Frame]) -> tuple[float, float, float]:
    """Median colour of the 1-pixel image borders of the training views."""
    px = torch.cat([torch.cat([f.rgb[0], f.rgb[-1], f.rgb[:, 0], f.rgb[:, -1]]) for f in frames])
    return tuple(float(v) for v in px.median(dim=0).values)


def field_box(cfg: TrainConfig, frames: list[Frame], points: torch.Tensor | None = None):
    """(lo, hi) (3,) metres: the object's twin box over the training states padded 10%, else a box
    derived from the cameras (and ``points``)."""
    box = object_bounds(cfg.object_dir, cfg.states) if (points is None and cfg.object_dir) else None
    if box is not None:
        pad = 0.1 * (box[1] - box[0]).clamp(min=1e-3)
        return box[0] - pad, box[1] + pad
    return camera_bounds(frames, points)


def needs_hulls(cfg: TrainConfig) -> bool:
    return not cfg.depth_init and (cfg.init in ("hull", "hull0") or cfg.hull_weight > 0 or cfg.hull_cover_weight > 0)


def build_hulls(cfg: TrainConfig, frames: list[Frame]):
    """Per-state visual hulls (pd2gs/hull.py ``HullGrid``) of the training views in the field box."""
    from pd2gs.hull import state_hulls

    lo, hi = field_box(cfg, frames)
    return state_hulls([f for f in frames if f.split == "train"], cfg.background, lo, hi,
                       cfg.hull_resolution, dilate=cfg.hull_dilate)


def build_field(cfg: TrainConfig, frames: list[Frame], hulls=None) -> DeformableField:
    """Canonical Gaussians from depth back-projection (cfg.depth_init), else from the RGB-only visual
    hull (pd2gs/hull.py; cfg.init == "hull": the union of the per-state hulls, "hull0": the hull of
    the first training state; the box when the hull is empty), else uniformly in the object's bounding
    box (its twin over the training states, padded 10%; without a twin, a box derived from the
    cameras); deformation MLP at identity; K = len(cfg.states) latents. ``hulls``: a precomputed
    ``HullGrid`` (else computed here when needed). ``cfg.background`` must already be set (the
    Trainer estimates it first)."""
    if cfg.init not in ("hull", "hull0", "box"):
        raise ValueError(f"TrainConfig.init must be 'box', 'hull' or 'hull0', got {cfg.init!r}")
    points = None
    if cfg.depth_init:
        points, colors = backproject_frames([f for f in frames if f.split == "train"])
    lo, hi = field_box(cfg, frames, points)
    if points is None and cfg.init in ("hull", "hull0"):
        from pd2gs.hull import sample_voxels

        hulls = hulls if hulls is not None else build_hulls(cfg, frames)
        mask = hulls.occ.any(0) if cfg.init == "hull" else hulls.occ[0]
        n_union = int(round(cfg.init_union_frac * cfg.init_points)) if cfg.init == "hull0" else 0
        hp = sample_voxels(hulls, mask, cfg.init_points - n_union, cfg.seed)
        if hp is not None and n_union > 0:  # a part hidden in the first state still gets some Gaussians
            extra = sample_voxels(hulls, hulls.occ.any(0), n_union, cfg.seed + 1)
            hp = torch.cat([hp, extra]) if extra is not None else hp
        if hp is not None:
            points, colors = hp, torch.full_like(hp, 0.5)
    if points is not None:
        g = init_from_points(points, colors, cfg.init_points, cfg.seed)
    else:
        g = init_from_bounds(lo, hi, cfg.init_points, cfg.seed)
    torch.manual_seed(cfg.seed)
    return DeformableField(g, len(cfg.states), cfg.deform, (lo + hi) / 2, float((hi - lo).norm() / 2))


def make_optimizer(cfg: TrainConfig, fld: DeformableField) -> torch.optim.Adam:
    g = fld.gaussians
    groups = [
        {"params": [g.means], "lr": cfg.lr_means * fld.extent, "name": "means"},
        {"params": [g.log_scales], "lr": cfg.lr_log_scales, "name": "log_scales"},
        {"params": [g.quats], "lr": cfg.lr_quats, "name": "quats"},
        {"params": [g.color_logits], "lr": cfg.lr_colors, "name": "color_logits"},
        {"params": [g.opacity_logits], "lr": cfg.lr_opacity, "name": "opacity_logits"},
        {"params": list(fld.mlp.parameters()), "lr": cfg.lr_mlp, "name": "mlp"},
        {"params": [fld.latents], "lr": cfg.lr_latents, "name": "latents"},
    ]
    return torch.optim.Adam(groups, eps=1e-15)


def render_frame(fld: DeformableField, latent: torch.Tensor, frame: Frame, background, backend: str, **kw):
    """Render the field deformed by ``latent`` (D,) into ``frame``'s camera (RenderOutput)."""
    d = fld.deform(latent, kw.pop("mask", None), kw.pop("base_latent", None))
    return render_deformed(fld, d, frame, background, backend, **kw)


def render_deformed(fld: DeformableField, d: DeformedGaussians, frame: Frame, background, backend: str, **kw):
    """Render already-deformed geometry ``d`` with the field's shared colours and opacities."""
    g = fld.gaussians
    w, h = frame.size
    return rasterize(d.means, d.quats, d.log_scales.exp(), g.colors, g.opacities, frame.K, frame.w2c,
                     w, h, background=torch.tensor(background), backend=backend, **kw)


class Trainer:
    """Owns the field, optimiser, sampler and schedule; ``run()`` trains to ``cfg.iters``."""

    def __init__(self, cfg: TrainConfig, frames: list[Frame], run_dir: Path | None = None):
        self.cfg = cfg
        self.frames = frames
        self.train = [f for f in frames if f.split == "train"]
        if not self.train:
            raise ValueError("no training views (split == 'train')")
        self.run_dir = Path(run_dir) if run_dir is not None else None
        torch.set_num_threads(cfg.threads)
        if cfg.background is None:
            cfg.background = estimate_background(self.train)
        hulls = build_hulls(cfg, frames) if needs_hulls(cfg) else None
        self.field = build_field(cfg, frames, hulls)
        self.hull_prior = None
        if hulls is not None and (cfg.hull_weight > 0 or cfg.hull_cover_weight > 0):
            from pd2gs.hull import HullPrior

            self.hull_prior = HullPrior(hulls, self.field.extent)
        self.opt = make_optimizer(cfg, self.field)
        self.stats = DensifyStats.zeros(self.field.gaussians.num)
        self.iteration = 0
        self.rng = np.random.default_rng(cfg.seed)
        self.gen = torch.Generator().manual_seed(cfg.seed + 1)
        self.order: list[int] = []
        self.history: list[dict] = []
        self.graph: NeighbourGraph | None = None

    # ---- schedule -------------------------------------------------------------------------
    def _set_lrs(self) -> None:
        frac = self.iteration / max(1, self.cfg.iters)
        for group in self.opt.param_groups:
            if group["name"] == "means":
                group["lr"] = self.cfg.lr_means * self.field.extent * 0.01 ** frac
            elif group["name"] == "mlp":
                group["lr"] = self.cfg.lr_mlp * 0.1 ** frac

    def join_iteration(self, k: int) -> int:
        """Iteration at which training state k becomes active (0 for all without the curriculum)."""
        K = len(self.cfg.states)
        if not self.cfg.curriculum or K < 2 or k == 0:
            return 0
        return int(round(k / (K - 1) * self.cfg.curriculum_frac * self.cfg.iters))

    def active_states(self) -> int:
        """Number of active states (a prefix of cfg.states) at the current iteration."""
        return sum(1 for k in range(len(self.cfg.states)) if self.join_iteration(k) <= self.iteration)

    def _next_frame(self) -> Frame:
        n_active = self.active_states()
        for k in range(1, n_active):
            if self.join_iteration(k) == self.iteration:  # a state joins: start from its predecessor
                with torch.no_grad():
                    self.field.latents[k] = self.field.latents[k - 1]
                self.order = []
        if not self.order:
            pool = [i for i, f in enumerate(self.train) if f.state < n_active]
            self.order = [pool[i] for i in self.rng.permutation(len(pool))]
        return self.train[self.order.pop()]

    def _rigidity(self, deformed_means: torch.Tensor) -> torch.Tensor | None:
        if self.cfg.rigidity_weight <= 0 or self.field.gaussians.num <= self.cfg.rigidity_k:
            return None
        if self.graph is None or self.graph.n != self.field.gaussians.num:
            self.graph = knn_graph(self.field.gaussians.means, self.cfg.rigidity_k)
        return isometry_loss(deformed_means, self.graph)

    def hull_factor(self) -> float:
        """Weight multiplier of the hull prior: 1 at the start, linearly 0 at hull_until_frac * iters."""
        end = self.cfg.hull_until_frac * self.cfg.iters
        return max(0.0, 1.0 - self.iteration / end) if end > 0 else 0.0

    def _hull_terms(self, means: torch.Tensor, k: int) -> torch.Tensor | float:
        hp, cfg = self.hull_prior, self.cfg
        f = self.hull_factor()
        if hp is None or f <= 0 or not hp.has(k):
            return 0.0
        out = 0.0
        if cfg.hull_weight > 0:
            out = out + f * cfg.hull_weight * hp.outside(means, k)
        if cfg.hull_cover_weight > 0:
            out = out + f * cfg.hull_cover_weight * hp.coverage(means, self.field.gaussians.opacities, k, self.gen)
        return out

    def step(self) -> dict:
        """One training iteration; returns {loss, psnr}."""
        cfg = self.cfg
        self._set_lrs()
        frame = self._next_frame()
        d = self.field.deform(self.field.latent(frame.state))  # kept: the priors below read it
        g = self.field.gaussians
        out = render_deformed(self.field, d, frame, cfg.background, cfg.backend)
        out.means2d.retain_grad()
        loss = photometric_loss(out.rgb, frame.rgb, cfg.lambda_dssim)
        rig = self._rigidity(d.means)
        if rig is not None:
            loss = loss + cfg.rigidity_weight * rig
        if cfg.scale_reg_weight > 0:
            loss = loss + cfg.scale_reg_weight * (d.log_scales - g.log_scales).abs().mean()
        loss = loss + self._hull_terms(d.means, frame.state)
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        self.iteration += 1
        it = self.iteration
        until = int(cfg.densify_until_frac * cfg.iters)
        if it < until and out.means2d.grad is not None:
            self.stats.add(out.means2d.grad, out.radii, *frame.size)
        self.opt.step()
        with torch.no_grad():
            q = self.field.gaussians.quats
            q /= q.norm(dim=-1, keepdim=True)
        info = {"loss": float(loss.detach()), "psnr": psnr(out.rgb, frame.rgb)}
        if it >= cfg.densify_from and it < until and it % cfg.densify_every == 0:
            info["densify"] = densify_and_prune(
                self.field.gaussians, self.opt, self.stats, cfg.densify_grad, self.field.extent,
                cfg.percent_dense, cfg.min_opacity, cfg.max_gaussians, self.gen)
            self.stats = DensifyStats.zeros(self.field.gaussians.num)
            self.graph = None
        if cfg.opacity_reset_every and it < until and it % cfg.opacity_reset_every == 0:
            reset_opacity(self.field.gaussians, self.opt)
        return info

    def run(self, progress: bool = True, stop_at: int | None = None) -> None:
        """Train until cfg.iters (or ``stop_at``), checkpointing every cfg.checkpoint_every
        iterations and at the end."""
        from tqdm import tqdm

        end = min(self.cfg.iters, stop_at or self.cfg.iters)
        bar = tqdm(total=self.cfg.iters, initial=self.iteration, disable=not progress, dynamic_ncols=True)
        ema = None
        while self.iteration < end:
            info = self.step()
            ema = info["psnr"] if ema is None else 0.9 * ema + 0.1 * info["psnr"]
            bar.update(1)
            bar.set_postfix(loss=f"{info['loss']:.4f}", psnr=f"{ema:.2f}", n=self.field.gaussians.num)
            if self.iteration % 50 == 0:
                self.history.append({"iter": self.iteration, "loss": info["loss"], "psnr": info["psnr"],
                                     "gaussians": self.field.gaussians.num})
            if self.run_dir is not None and self.iteration % self.cfg.checkpoint_every == 0:
                self.save()
        bar.close()
        if self.run_dir is not None:
            self.save()

    # ---- evaluation ---------------------------------------------------------------------------
    @torch.no_grad()
    def evaluate(self, split: str = "test") -> dict:
        """Mean PSNR per training state on ``split`` views ({state id: dB}, plus 'mean')."""
        res: dict[str, list[float]] = {}
        for f in self.frames:
            if f.split != split:
                continue
            out = render_frame(self.field, self.field.latent(f.state), f, self.cfg.background, self.cfg.backend)
            res.setdefault(self.cfg.states[f.state], []).append(psnr(out.rgb.clamp(0, 1), f.rgb))
        table = {k: float(np.mean(v)) for k, v in res.items()}
        if table:
            table["mean"] = float(np.mean(list(table.values())))
        return table

    # ---- checkpoints ---------------------------------------------------------------------------
    def state_dict(self) -> dict:
        return {"iteration": self.iteration, "field": self.field.state_dict(), "extent": self.field.extent,
                "opt": self.opt.state_dict(), "stats": (self.stats.grad_sum, self.stats.count),
                "rng": self.rng.bit_generator.state, "gen": self.gen.get_state(),
                "torch_rng": torch.get_rng_state(), "py_rng": random.getstate(),
                "order": list(map(int, self.order)), "history": self.history,
                "graph": None if self.graph is None else (self.graph.idx, self.graph.rest, self.graph.scale)}

    def load_state_dict(self, st: dict) -> None:
        self.field.gaussians.resize_like({k.split(".", 1)[1]: v for k, v in st["field"].items()
                                          if k.startswith("gaussians.")})
        self.field.load_state_dict(st["field"])
        self.opt = make_optimizer(self.cfg, self.field)
        self.opt.load_state_dict(st["opt"])
        self.stats = DensifyStats(*st["stats"])
        self.iteration = st["iteration"]
        self.rng.bit_generator.state = st["rng"]
        self.gen.set_state(st["gen"])
        torch.set_rng_state(st["torch_rng"])
        random.setstate(st["py_rng"])
        self.order = list(st["order"])
        self.history = st["history"]
        self.graph = NeighbourGraph(*st["graph"]) if st.get("graph") is not None else None  # resume bit-exact

    def save(self) -> Path:
        """Atomically write RUN/checkpoint.pt (and config.json, cameras.json)."""
        assert self.run_dir is not None
        self.run_dir.mkdir(parents=True, exist_ok=True)
        path = self.run_dir / "checkpoint.pt"
        tmp = path.with_suffix(".pt.tmp")
        torch.save(self.state_dict(), tmp)
        tmp.replace(path)
        write_json_atomic(self.run_dir / "config.json", asdict(self.cfg))
        cams = [{"state": self.cfg.states[f.state], "split": f.split, "view": f.view_id,
                 "K": f.K.tolist(), "w2c": f.w2c.tolist(), "size": list(f.size)} for f in self.frames]
        write_json_atomic(self.run_dir / "cameras.json", cams)
        return path


def write_json_atomic(path: Path, obj) -> None:
    """JSON written atomically by :func:`rsart.io.write_json` (NaN/inf written as null)."""
    def clean(x):
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [clean(v) for v in x]
        return x
    write_json(path, clean(obj))


def load_field(run_dir: str | Path) -> tuple[TrainConfig, DeformableField]:
    """Config and trained field of a run folder (config.json + checkpoint.pt)."""
    from pd2gs.gaussians import CanonicalGaussians

    run = Path(run_dir)
    cfg = TrainConfig.from_json(json.loads((run / "config.json").read_text()))
    st = torch.load(run / "checkpoint.pt", map_location="cpu", weights_only=False)
    g = CanonicalGaussians(torch.zeros(1, 3), torch.zeros(1, 3), torch.full((1, 3), 0.5))
    fld = DeformableField(g, len(cfg.states), cfg.deform, torch.zeros(3), float(st["extent"]))
    g.resize_like({k.split(".", 1)[1]: v for k, v in st["field"].items() if k.startswith("gaussians.")})
    fld.load_state_dict(st["field"])
    return cfg, fld


class TrainedModel:
    """A trained :class:`~pd2gs.deform.DeformableField` seen as per-state Gaussians (what discovery reads).

    ``state_gaussians(sid)`` -> dict of numpy-able tensors: means (N, 3) m, quats (N, 4) wxyz, scales (N, 3)
    standard deviations, colors (N, 3), opacities (N,); ``interpolate(a, b, t)`` the same at the latent
    lerp(α_a, α_b, t).
    """

    def __init__(self, field, state_ids: list[str], background: tuple[float, float, float] | None = None):
        self.field = field
        self.state_ids = list(state_ids)
        self.background = background  # the trainer's render background (RGB in [0, 1])

    def _gaussians(self, latent: torch.Tensor) -> dict:
        with torch.no_grad():
            d = self.field.deform(latent)
            g = self.field.gaussians
            return {"means": d.means, "quats": d.quats, "scales": d.log_scales.exp(), "colors": g.colors,
                    "opacities": g.opacities}

    def state_gaussians(self, sid: str) -> dict:
        return self._gaussians(self.field.latent(self.state_ids.index(sid)))

    def interpolate(self, a: str, b: str, t: float) -> dict:
        return self._gaussians(self.field.interpolate(self.state_ids.index(a), self.state_ids.index(b), t))


def train_object(obj_dir: Path, run_dir: Path, cfg, progress: bool = True) -> TrainedModel:
    """Train (or resume / reuse a finished run in ``run_dir``) and return the trained model."""
    from .data import load_frames

    done = run_dir / "metrics.json"
    if done.is_file() and (run_dir / "checkpoint.pt").is_file():
        tcfg, field = load_field(run_dir)
        return TrainedModel(field, tcfg.states, tcfg.background)
    cfg.object_dir = str(obj_dir)
    cfg.states, frames = load_frames(obj_dir, cfg.states or None, cfg.size, with_depth=cfg.depth_init)
    trainer = Trainer(cfg, frames, run_dir)
    if (run_dir / "checkpoint.pt").is_file():
        trainer.load_state_dict(torch.load(run_dir / "checkpoint.pt", weights_only=False))
    run_dir.mkdir(parents=True, exist_ok=True)
    write_json_atomic(run_dir / "config.json", asdict(cfg))
    t0 = time.perf_counter()
    trainer.run(progress=progress)
    write_json_atomic(done, {"test_psnr": trainer.evaluate("test"), "train_psnr": trainer.evaluate("train"),
                             "iterations": trainer.iteration, "seconds": time.perf_counter() - t0,
                             "gaussians": trainer.field.gaussians.num})
    return TrainedModel(trainer.field, cfg.states, cfg.background)
