"""Coarse joint search: every movable body's joint, and the Gaussians it owns, chosen among many hypotheses
before the gradient fit, by how well the posed Gaussians agree with the images.

A gradient fit of a joint started far from the truth stalls: a Kabsch estimate on a stage-1 cluster that
mixes two parts, or on a field that moved only some of a part's Gaussians, can point a hinge 30° off or call
a slide a hinge, and the photometric loss has no slope that leads back. Measured on eyeglasses-0000 (docs/
pd2gs-parts.md): with each Gaussian given to its true part, this search puts both temples' hinges within
1.3° (the Kabsch joints on the same Gaussians were 29° and 53° off), and the fit then ends within 0.2°.

**Score, no rendering.** A hypothesis is scored by projecting Gaussians, posed in every state, into up to
``views_per_state`` training views per state (:class:`ConsistencyViews`). A Gaussian's cost in one state
is the mean over the views of its distance outside the object's silhouette (pixels, truncated at ``tau_px``,
scaled to [0, 1]; 1 outside the image: a point of the object lies inside every view's silhouette) plus the
median over the views of its mean absolute RGB difference from the image (a view where it is occluded is
outvoted); then the mean over states. A body is scored on its own Gaussians and on the other movable
bodies' within ``reach`` x the object's extent (a fragment of a part is scored with the rest of the part),
each counting ``min(cost under the hypothesis, alt)``, weighted by opacity: ``alt`` is the cost when not
moving (and, for another body's Gaussian, under that body's joint). A cluster that holds some base
Gaussians, or half a part, is so scored by the Gaussians the hypothesis explains.

**Hypotheses**, per body:

* axes: the current one, the principal directions of the scored Gaussians and ``n_axes`` directions spread
  evenly over the half sphere (about 18° apart at 64);
* revolute pivots: the current one and a ``pivot_grid`` x ``pivot_grid`` grid over the scored Gaussians'
  extent (padded by 10 %) in the plane orthogonal to the axis; prismatic: no pivot;
* values linear in the state's position between the reference state (value 0) and the one farthest from
  it (``ramp``), the far value on a grid: angles in [-pi, pi), slides in [-1.5, 1.5] x the extent;
* scored on ``coarse_points`` of the Gaussians; the best ``refine_starts`` of each type that differ (axis
  > 10° or hinge line > 10 % of the extent apart) and the current joint are refined by a local pattern
  search (axis tilted on a cone, pivot moved in the plane, all values by the ramp; the steps halve
  ``levels`` times) on the same points, the best of them once more on all, then each state's value alone.

The result replaces the body's joint only where it scores lower than the current joint and explains at
least ``min_explained`` of the cost its Gaussians have when not moving: where a part's closed position
stays inside the object's silhouette and matches the colours behind it (a white refrigerator's door), no
hypothesis is much better than not moving, and the search leaves the joint alone.

**All bodies at once, ownership left alone.** Every body is searched on the *starting* model (the other
bodies at their starting joints) and all picks are set together, as :mod:`.surfaces` does; the Gaussians stay
with their owners, and the gradient fit's own re-assignment moves them. Searched largest first instead, each body
on the model the earlier searches had changed, with Gaussians re-assigned by the projection score after each,
the refrigerator's left door took the right door's Gaussians and the right door's hinge was never found
(docs/pd2gs-experiments.md, thirty-fifth entry). Measured on six stage-1 fields, two seeds
(benchmarks/results/pd2gs-rsart-synth-6-zen3-search-together.md): kept on four, this start then wins model
selection on all four in both seeds, and the revolute Part Motion mean drops (68.1° -> 56.8°, 57.1° -> 54.3°).

**Rendered turn and check.** The projection score finds a hinge's line but can be fooled on its turn, so
every hinge then has its far value chosen again by rendering (:func:`rendered_turn`: ``turn_steps`` far
values, 15° apart at 25, then twice a third of the step on either side of the best, 5° and 1.7°), each with the
other bodies at their picks; the whole result is kept only if the
model's rendered held-out loss (:func:`rendered_loss` on every held-out view: what model selection scores)
is lower than the starting model's. The gradient fit (:mod:`.fit`) refines everything after.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch
import torch.nn.functional as F

from pd2gs.data import Frame

from .fit import evaluate_views
from .model import ArticulatedGaussians, axis_angle_matrix
from .ownership import view_subset

Hypothesis = tuple[str, np.ndarray, np.ndarray, np.ndarray]  # (type, unit axis (3,), pivot (3,), values (S,))


@dataclass
class SearchConfig:
    """Grid sizes and rules of :func:`search_joints` (see the module doc). ``max_points``: a body is scored
    on at most this many of its own most opaque Gaussians and as many of its neighbours'; ``ramp`` (S,)
    the far value's share in each state (None: linear from the ``ref`` state). ``turn_views``: train views
    per moved state rendered to choose each hinge's turn among ``turn_steps`` far values in [-pi, pi], then
    ``turn_refine`` times the two values a third of the last step either side of the best;
    ``silhouette``, ``background``, ``backend``: the rendered score's, as the fit's."""

    n_axes: int = 64
    pivot_grid: int = 5
    angle_steps: int = 24
    slide_steps: int = 24
    views_per_state: int = 8
    max_points: int = 256
    coarse_points: int = 64
    reach: float = 0.25
    refine_starts: int = 4
    levels: int = 5
    tau_px: float = 6.0
    min_explained: float = 0.5
    ramp: list[float] | None = None
    batch: int = 256
    turn_views: int = 4
    turn_steps: int = 25
    turn_refine: int = 2
    silhouette: float = 0.5
    background: tuple[float, float, float] = (1.0, 1.0, 1.0)
    backend: str = "cpu"


@dataclass
class SearchResult:
    """Per body the chosen joint, its projection scores and (hinges) its rendered turn's scores; ``held_out``
    the model's rendered loss on the held-out views before and after (None without held-out views);
    ``kept``: whether the result replaced the starting model."""

    chosen: dict[int, dict] = field(default_factory=dict)
    held_out: tuple[float, float] | None = None
    kept: bool = True


class ConsistencyViews:
    """The views a search projects into, per state: images (V, 4, H, W) = RGB in [0, 1] and the truncated
    distance outside the silhouette (0 inside, 1 at ``tau_px`` pixels and beyond; 0 everywhere where a view
    has no mask) and the projections K [R | t] (V, 3, 4) (OpenCV)."""

    def __init__(self, frames: list[Frame], masks, n_states: int, split: str = "train", per_state: int = 8,
                 tau_px: float = 6.0):
        from scipy.ndimage import distance_transform_edt

        self.views = []
        chosen = set(view_subset(frames, split, per_state * n_states))
        for s in range(n_states):
            imgs, Ks, w2cs = [], [], []
            for i in sorted(chosen):
                f = frames[i]
                if f.state != s:
                    continue
                h, w = f.rgb.shape[:2]
                if imgs and imgs[0].shape[1:] != (h, w):
                    raise ValueError(f"frames: the views of state {s} differ in size ({f.view_id})")
                sil = torch.zeros(h, w)
                m = masks[i] if masks is not None else None
                if m is not None:
                    sil = torch.from_numpy(np.minimum(distance_transform_edt(m.numpy() < 0.5) / tau_px, 1.0)).float()
                imgs.append(torch.cat([f.rgb.permute(2, 0, 1).float(), sil[None]], 0))
                Ks.append(f.K.double())
                w2cs.append(f.w2c.double())
            if not imgs:
                raise ValueError(f"frames: state {s} has no {split!r} view")
            proj = torch.stack(Ks) @ torch.stack(w2cs)[:, :3]  # (V, 3, 4) pixels from world points
            self.views.append((torch.stack(imgs), proj.float()))

    def cost(self, X: torch.Tensor, colors: torch.Tensor) -> torch.Tensor:
        """Posed points X (H, S, M, 3) world frame, their colours (M, 3) -> (H, M): per state the mean over
        its views of the silhouette distance (1 outside the image: a point of the object is inside every
        view's silhouette) plus the median over views of the mean |RGB difference| (a view where the point
        is occluded is outvoted), mean over states."""
        H, S, M, _ = X.shape
        X = X.float()
        out = []
        for s in range(S):
            imgs, proj = self.views[s]
            h, w = imgs.shape[2:]
            cam = torch.einsum("vij,nj->vni", proj[:, :, :3], X[:, s].reshape(-1, 3)) + proj[:, None, :, 3]
            z = cam[..., 2]
            uv = cam[..., :2] / z.clamp_min(1e-9)[..., None]
            grid = (2 * uv + 1) / torch.tensor([w, h], dtype=uv.dtype) - 1  # pixel centres at integers (OpenCV)
            smp = F.grid_sample(imgs, grid[:, None], mode="bilinear", padding_mode="border", align_corners=False)[:, :, 0]
            inside = (z > 1e-9) & (grid.abs() <= 1).all(-1)
            sil = torch.where(inside, smp[:, 3], 1.0).mean(0)
            col = (smp[:, :3] - colors.T.repeat(1, H)[None]).abs().mean(1)
            col = torch.where(inside, col, 1.0).median(0).values
            out.append((sil + col).reshape(H, M))
        return torch.stack(out).mean(0)


def joint_poses(kind: str, axes: torch.Tensor, pivots: torch.Tensor, values: torch.Tensor
                ) -> tuple[torch.Tensor, torch.Tensor]:
    """One joint type, H hypotheses: unit axes (H, 3), pivots (H, 3), values (H, S) -> R (H, S, 3, 3),
    t (H, S, 3) (x_world = R x + t)."""
    H, S = values.shape
    u = axes[:, None].expand(H, S, 3)
    if kind == "revolute":
        R = axis_angle_matrix(u, values)
        return R, pivots[:, None] - (R @ pivots[:, None, :, None])[..., 0]
    return torch.eye(3, dtype=axes.dtype).expand(H, S, 3, 3), values[..., None] * u


def _ramp(num_states: int, ref: int) -> np.ndarray:
    """(S,) 0 at ``ref``, 1 at the state farthest from it, linear in the state index."""
    idx = np.arange(num_states, dtype=np.float64) - ref
    far = np.abs(idx).max() or 1.0
    return idx / far


def half_sphere(n: int) -> np.ndarray:
    """(n, 3) unit directions spread evenly over the half sphere z > 0 (a Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = i / n
    r = np.sqrt(1 - z * z)
    phi = i * math.pi * (3 - math.sqrt(5))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)


def _plane(a: np.ndarray) -> np.ndarray:
    """(3, 2) orthonormal basis of the plane orthogonal to the unit vector a."""
    return np.linalg.svd(np.eye(3) - np.outer(a, a))[0][:, :2]


class _Body:
    """The Gaussians one body's hypotheses are scored on (a hypothesis is the body's joint relative to its
    parent, posed with the parent's current pose in every state): the body's own (its ``max_points`` most opaque)
    and those of the other movable bodies within ``reach`` x the object's extent of them (as many at most:
    a fragment of a part is scored together with the rest of that part), as canonical points P (M, 3),
    colours (M, 3), weights (M,) = opacity, and ``alt`` (M,) each one's cost under the better of not moving
    and its current owner's joint."""

    def __init__(self, model: ArticulatedGaussians, b: int, views: ConsistencyViews, cfg: SearchConfig,
                 costs: torch.Tensor):
        from scipy.spatial import cKDTree

        g = model.gaussians
        means = g.means.detach().double()
        op = g.opacities.detach().reshape(-1).float()
        lab = model.labels()

        def top(idx):
            return idx[torch.argsort(op[idx], descending=True)[:cfg.max_points]]

        own = top(torch.nonzero(lab == b)[:, 0])
        others = torch.nonzero((lab != b) & (lab > 0))[:, 0]
        if len(own) and len(others):
            extent = float(torch.linalg.norm(means.amax(0) - means.amin(0)))
            d, _ = cKDTree(means[own].numpy()).query(means[others].numpy())
            others = top(others[torch.from_numpy(d <= cfg.reach * extent)])
        idx = torch.cat([own, others])
        self.n_own = len(own)
        self.P = means[idx]
        self.colors = g.colors.detach()[idx].float()
        self.w = op[idx].clamp_min(1e-6)
        self.alt = costs[idx, 0].clone()  # the body's own: not moving; the others: also their owner's joint
        self.alt[len(own):] = torch.minimum(self.alt[len(own):], costs[others, lab[others]])
        self.views, self.batch = views, cfg.batch
        # a hypothesis is the body's joint relative to its parent: world pose = parent's pose o joint
        poses = [model.body_poses(s) for s in range(model.num_states)]
        p = model.parent[b]
        self.parent_R = torch.stack([q.R[p] for q in poses]).detach().double()  # (S, 3, 3)
        self.parent_t = torch.stack([q.t[p] for q in poses]).detach().double()  # (S, 3)

    def subset(self, n: int) -> "_Body":
        """A copy scored on at most n of the points (spread evenly over the own ones and the others)."""
        if len(self.P) <= n:
            return self
        keep = torch.from_numpy(np.unique(np.linspace(0, len(self.P) - 1, n).round().astype(np.int64)))
        out = object.__new__(_Body)
        out.__dict__.update(self.__dict__)
        out.P, out.colors, out.w, out.alt = self.P[keep], self.colors[keep], self.w[keep], self.alt[keep]
        out.n_own = int((keep < self.n_own).sum())
        return out

    def score(self, kind: str, axes, pivots, values) -> torch.Tensor:
        """(H,) sum_i w_i min(c_i(h), alt_i) / sum_i w_i for H hypotheses of one ``kind``."""
        axes, pivots, values = (torch.as_tensor(np.asarray(x), dtype=torch.float64) for x in (axes, pivots, values))
        out = []
        for i in range(0, len(axes), self.batch):
            R, t = joint_poses(kind, axes[i:i + self.batch], pivots[i:i + self.batch], values[i:i + self.batch])
            R, t = self.parent_R @ R, (self.parent_R @ t[..., None])[..., 0] + self.parent_t
            c = self.views.cost(torch.einsum("hsij,mj->hsmi", R, self.P) + t[:, :, None], self.colors)
            out.append((torch.minimum(c, self.alt[None]) * self.w).sum(1) / self.w.sum())
        return torch.cat(out)


def _best(body: _Body, kind: str, hyps: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> tuple[float, int]:
    sc = body.score(kind, [h[0] for h in hyps], [h[1] for h in hyps], [h[2] for h in hyps])
    k = int(sc.argmin())
    return float(sc[k]), k


def search_body(model: ArticulatedGaussians, b: int, views: ConsistencyViews, ramp: np.ndarray,
                cfg: SearchConfig) -> tuple[float, float, Hypothesis]:
    """Body b's best joint by the score of ``views`` (anything with ``cost(X (H, S, M, 3), colors (M, 3)) ->
    (H, M)``: :class:`ConsistencyViews`, or :class:`.surfaces.SurfaceViews`) -> (current joint's score, best
    score, best hypothesis); the current joint is returned when nothing scores lower. A hypothesis is b's
    joint relative to its parent, posed with the parent's current motion (a chained child is searched on its
    parent; :func:`pd2gs.articulated.select.searched_reparent`). See the module doc for the hypotheses."""
    j = b - 1
    body = _Body(model, b, views, cfg, pose_costs(model, views))
    cur: Hypothesis = (model.joint_types[j], model.unit_axes[j].detach().double().numpy(),
                       model.pivots[j].detach().double().numpy(), model.values[:, j].detach().double().numpy())
    if body.n_own < 3:
        return math.inf, math.inf, cur
    start = float(body.score(cur[0], cur[1][None], cur[2][None], cur[3][None])[0])
    P = body.P.numpy()
    centre = P.mean(0)
    extent = float(np.linalg.norm(np.ptp(P, axis=0))) or 1e-3
    axes = [cur[1]] + list(np.linalg.svd(P - centre, full_matrices=False)[2]) + list(half_sphere(cfg.n_axes))
    angles = np.linspace(-math.pi, math.pi, cfg.angle_steps, endpoint=False)
    slides = np.linspace(-1.5, 1.5, cfg.slide_steps) * extent
    rev, pri = [], []
    for a in axes:
        a = a / np.linalg.norm(a)
        e = _plane(a)
        q = (P - centre) @ e
        lo, hi = q.min(0), q.max(0)
        pad = 0.1 * (hi - lo)
        xs, ys = (np.linspace(lo[k] - pad[k], hi[k] + pad[k], cfg.pivot_grid) for k in (0, 1))
        for p in [cur[2]] + [centre + e @ np.array([x, y]) for x in xs for y in ys]:
            rev += [(a, p, v * ramp) for v in angles if abs(v) > 1e-9]
        pri += [(a, centre, v * ramp) for v in slides if abs(v) > 1e-9]
    starts: list[Hypothesis] = [cur]
    coarse = body.subset(cfg.coarse_points)
    for kind, hyps in (("revolute", rev), ("prismatic", pri)):
        sc = coarse.score(kind, [h[0] for h in hyps], [h[1] for h in hyps], [h[2] for h in hyps])
        for k in torch.argsort(sc).tolist():
            a, p, _ = hyps[k]
            if all(t != kind or abs(float(a @ a2)) < 0.985 or np.linalg.norm(np.cross(p - p2, a)) > 0.1 * extent
                   for t, a2, p2, _ in starts[1:]):
                starts.append((kind, *hyps[k]))
            if sum(h[0] == kind for h in starts[1:]) >= cfg.refine_starts:
                break
    # every start refined on the coarse points; the best of them once more, at the finest steps, on all
    refined = [_refine(coarse, h, float(coarse.score(h[0], h[1][None], h[2][None], h[3][None])[0]), ramp,
                       extent, cfg) for h in starts]
    h = min(refined, key=lambda r: r[0])[1]
    score, h = _refine(body, h, float(body.score(h[0], h[1][None], h[2][None], h[3][None])[0]), ramp, extent,
                       cfg, first_level=cfg.levels - 2)
    still = float((body.alt * body.w).sum() / body.w.sum())  # the score if the body did not move at all
    if score < start and score < (1.0 - cfg.min_explained) * still:
        return start, score, h
    return start, start, cur


def _refine(body: _Body, best: Hypothesis, best_score: float, ramp: np.ndarray, extent: float,
            cfg: SearchConfig, first_level: int = 0) -> tuple[float, Hypothesis]:
    """Local pattern search from one hypothesis: the axis tilted on a cone, the pivot moved in the plane,
    the far value; the steps halve ``cfg.levels`` times; then each state's value on its own."""
    kind = best[0]
    d_axis, d_piv = math.radians(10.0), 0.5 * extent / max(1, cfg.pivot_grid - 1)
    d_val = (math.pi / cfg.angle_steps) if kind == "revolute" else 1.5 * extent / cfg.slide_steps
    d_axis, d_piv, d_val = (x / 2 ** max(0, first_level) for x in (d_axis, d_piv, d_val))
    tilts = [np.zeros(2)] + [np.array([math.cos(t), math.sin(t)]) for t in np.arange(8) * math.pi / 4]
    for _ in range(max(0, first_level), cfg.levels):
        improved = True
        while improved:
            _, a0, p0, v0 = best
            e0, hyps = _plane(a0), []
            for t in tilts:
                a = a0 + e0 @ t * math.tan(d_axis)
                a = a / np.linalg.norm(a)
                e = _plane(a)
                pivots = [p0] if kind == "prismatic" else [p0 + e @ np.array([x, y]) * d_piv
                                                           for x in (-1, 0, 1) for y in (-1, 0, 1)]
                hyps += [(a, p, v0 + dv * ramp) for p in pivots for dv in (-d_val, 0.0, d_val)]
            s, k = _best(body, kind, hyps)
            improved = s < best_score - 1e-7
            if improved:
                best_score, best = s, (kind, *hyps[k])
        d_axis, d_piv, d_val = d_axis / 2, d_piv / 2, d_val / 2
    vals = best[3].copy()
    for st in np.flatnonzero(ramp != 0):
        for dv in (4 * d_val, 2 * d_val, d_val):
            hyps = [(best[1], best[2], vals + dv * sgn * (np.arange(len(vals)) == st)) for sgn in (-1, 0, 1)]
            s, k = _best(body, kind, hyps)
            if s < best_score - 1e-7:
                best_score, vals = s, hyps[k][2]
    return best_score, (kind, best[1], best[2], vals)


def _set_joint(model: ArticulatedGaussians, j: int, t: str, axis, pivot, values) -> None:
    model.joint_types[j] = t
    model.axes.data[j] = torch.as_tensor(np.asarray(axis), dtype=model.axes.dtype)
    model.pivots.data[j] = torch.as_tensor(np.asarray(pivot), dtype=model.pivots.dtype)
    model.values.data[:, j] = torch.as_tensor(np.asarray(values), dtype=model.values.dtype)


@torch.no_grad()
def pose_costs(model: ArticulatedGaussians, views: ConsistencyViews) -> torch.Tensor:
    """(N, K+1) every Gaussian's consistency cost when posed with each body (column 0: the base)."""
    g = model.gaussians
    S = model.num_states
    poses = [model.body_poses(s) for s in range(S)]
    R = torch.stack([torch.stack([p.R[b] for p in poses]) for b in range(model.num_bodies)]).double()
    t = torch.stack([torch.stack([p.t[b] for p in poses]) for b in range(model.num_bodies)]).double()
    X = torch.einsum("bsij,nj->bsni", R, g.means.detach().double()) + t[:, :, None]
    return views.cost(X, g.colors.detach().float()).T


def rendered_loss(model: ArticulatedGaussians, frames: list[Frame], idx: list[int], masks, cfg: SearchConfig
                  ) -> float:
    """:func:`.fit.evaluate_views` (render L1 + ``cfg.silhouette`` x |alpha - mask|, what model selection
    scores) on the frames ``idx``."""
    sub = [frames[i] for i in idx]
    split = sub[0].split if sub else "train"
    return evaluate_views(model, sub, split, cfg.background, cfg.backend,
                          None if masks is None else [masks[i] for i in idx], cfg.silhouette)


@torch.no_grad()
def rendered_turn(model: ArticulatedGaussians, j: int, frames: list[Frame], masks, ramp: np.ndarray,
                  cfg: SearchConfig) -> tuple[float, float]:
    """Hinge j's turn chosen by rendering: its values set to ``v * ramp`` for ``cfg.turn_steps`` far values
    v in [-pi, pi] (and its current values), then ``cfg.turn_refine`` times for the two far values a third of
    the last step either side of the best so far, each scored by :func:`rendered_loss` on ``cfg.turn_views``
    train views per moved state; the lowest kept, in place -> (current score, chosen score).

    Coarse to fine because the renders are the search's main cost: on six stored fields the 25 + 4 values
    chose turns whose held-out loss is within 0.7 % of a 73-value (5°) grid's, either way, in 0.35x its time
    (docs/pd2gs-experiments.md, thirty-ninth entry).

    The projection score finds a lid's hinge line but can prefer a turn past the truth (woven_basket-0000:
    3.49 rad against 1.35, docs/pd2gs-experiments.md, seventeenth entry): a point cloud turned the wrong
    way still lands inside the silhouette on colours like its own. A render also sees what the posed part
    hides and uncovers."""
    moved = set(np.flatnonzero(ramp != 0).tolist())
    idx = [i for i in view_subset(frames, "train", cfg.turn_views * len(ramp)) if frames[i].state in moved]
    cur = model.values.data[:, j].clone()
    start = rendered_loss(model, frames, idx, masks, cfg)
    best, best_v = start, cur
    far = int(np.argmax(np.abs(ramp)))
    best_far = float(cur[far]) / float(ramp[far]) if ramp[far] else 0.0  # the far value refinements centre on
    trials = [float(v) for v in np.linspace(-math.pi, math.pi, cfg.turn_steps)]
    step = 2 * math.pi / (cfg.turn_steps - 1)
    for level in range(cfg.turn_refine + 1):  # the grid, then around the best at a third of the step each time
        if level:
            step /= 3.0
            trials = [best_far - step, best_far + step]
        for v in trials:
            cand = torch.as_tensor(v * ramp, dtype=cur.dtype)
            model.values.data[:, j] = cand
            sc = rendered_loss(model, frames, idx, masks, cfg)
            if sc < best:
                best, best_v, best_far = sc, cand, v
    model.values.data[:, j] = best_v
    return start, best


def search_bodies(model: ArticulatedGaussians, views, ramp: np.ndarray, cfg: SearchConfig) -> dict[int, dict]:
    """Every movable body's joint by :func:`search_body` on the *starting* model, then all set together, in
    place (a body searched after another had moved chooses differently; see the module doc) -> per body
    {"type", "score_before", "score_after"}. ``views``: anything with the :class:`ConsistencyViews` cost."""
    found = {b: search_body(model, b, views, ramp, cfg) for b in range(1, model.num_bodies)}
    for b, (_, _, h) in found.items():
        _set_joint(model, b - 1, *h)
    return {b: {"type": h[0], "score_before": before, "score_after": after} for b, (before, after, h) in found.items()}


@torch.no_grad()
def search_joints(model: ArticulatedGaussians, frames: list[Frame], masks=None, ref: int = 0,
                  cfg: SearchConfig | None = None) -> SearchResult:
    """Every movable body's joint searched on the starting model, all set together, every hinge's turn
    chosen by rendering, in place; ownership is left alone, and the starting model is restored when the
    held-out views do not confirm the result (see the module doc). ``masks``: per frame the object
    silhouette (H, W) or None (then colour alone scores)."""
    cfg = cfg or SearchConfig()
    S = model.num_states
    if not any(f.split == "train" for f in frames):
        raise ValueError("frames: the joint search needs training views (split 'train')")
    if cfg.turn_views < 1 or cfg.turn_steps < 2 or cfg.turn_refine < 0:
        raise ValueError(f"cfg: turn_views ({cfg.turn_views}) must be >= 1, turn_steps ({cfg.turn_steps}) >= 2 and "
                         f"turn_refine ({cfg.turn_refine}) >= 0")
    views = ConsistencyViews(frames, masks, S, "train", cfg.views_per_state, cfg.tau_px)
    ramp = np.asarray(cfg.ramp, dtype=np.float64) if cfg.ramp is not None else _ramp(S, ref)
    saved = {k: v.detach().clone() for k, v in model.state_dict().items()}
    types = list(model.joint_types)
    held = [i for i, f in enumerate(frames) if f.split == "test"]
    before = rendered_loss(model, frames, held, masks, cfg) if held else None
    res = SearchResult()
    res.chosen = search_bodies(model, views, ramp, cfg)
    for b in res.chosen:
        if model.joint_types[b - 1] == "revolute":
            res.chosen[b]["rendered_turn"] = rendered_turn(model, b - 1, frames, masks, ramp, cfg)
    if before is not None:
        after = rendered_loss(model, frames, held, masks, cfg)
        res.held_out = (before, after)
        if after >= before:
            model.load_state_dict(saved)
            model.joint_types[:] = types
            res.kept = False
    return res
