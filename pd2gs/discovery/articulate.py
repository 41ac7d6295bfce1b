"""Photometric articulation fit (ours): joints refined by rendering the *rigidly articulated* field.

The paper reads each joint off the deformation field's Gaussian centres (Kabsch between two states,
:mod:`.kinematics`). On 2 CPU cores our fields are trained at 160x120 for 3000 iterations, and the
learned deformation moves only part of a part's Gaussians rigidly, so those centre-based joints are
noisy (docs/pd2gs-parts.md). This step keeps the discovered part labels and the reference-state
Gaussians and replaces the deformation by the articulation model itself: in state k, part p's
Gaussians move by its joint,

    revolute:  mu' = R(u, theta_k) (mu - o) + o,   q' = q(u, theta_k) (x) q
    prismatic: mu' = mu + d_k u,                   q' = q

(label 0 stays put), and (u, o, theta_k | d_k) are found against the captured training images of every
state with the L1 photometric loss, in four steps:

1. grid search (forward renders only): axes from the centre-based estimate and the part's principal
   directions, pivots at the part's centroid / the estimate's pivot / the corners of its extent, the
   far state's value on a grid; then a finer pivot grid about the best axis; then each other state's
   value on the grid. Both joint types are searched.
2. Adam on all joints through the differentiable rasterizer.
3. type choice: the other type is fitted from its own search result; the lower held-out loss wins,
   revolute needing a relative margin (a revolute joint with a far pivot can imitate a slide).
   (A part whose centre-based joint renders no worse on held-out views keeps that joint.)
3b. chains: each part is also fitted as hanging from each movable part it touches (its motion is then
   its parent's followed by its own joint, whose axis and pivot are given at the reference state); the
   chain is kept when it lowers the error over the part's own pixels by ``chain_margin``. The submitted
   joint of a chained part is then relative to its parent, as the benchmark's ground truth is.
3c. parts the images do not support: a part whose own pixels render no worse with its joint held still
   joins the static base; two touching parts one of whose joints moves both as well merge (a field that
   does not move a part rigidly splits it into several k-means clusters).
4. relabelling: each Gaussian takes the part under whose motion its colour agrees best with the
   captured pixels in the other states (multi-view colour consistency), then step 2 again.

Gaussians' appearance and reference geometry stay fixed (letting them move with the joints measured
worse: the joints drifted from the truth on storage-0001, docs/pd2gs-parts.md).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
import torch

from rsart.camera import Camera

from pd2gs.deform import quat_multiply
from pd2gs.render.projection import quat_to_rotmat

from .field import StateField
from .kinematics import EPS, JointEstimate

Views = list[list[tuple[Camera, np.ndarray]]]  # views[k] = [(camera, rgb uint8 (H, W, 3))] of state k


@dataclass
class FitSettings:
    """Optimiser settings of :func:`fit_articulation` (ours; see docs/pd2gs-parts.md)."""

    iters: int = 300             # Adam steps per fit (one random training view per step)
    lr_axis: float = 0.01        # on the unnormalised axis vector (unit at the start)
    lr_pivot: float = 0.01       # x part extent
    lr_angle: float = 0.01       # rad
    lr_slide: float = 0.01       # x part extent
    eval_views: int = 4          # held-out views per state for the loss that picks the type
    type_margin: float = 0.01    # revolute must beat prismatic's held-out loss by this fraction
    choose_type: bool = True     # False: keep the types of the input joints
    search: bool = True          # grid search of axis/pivot/value hypotheses before the gradient fit
    search_views: int = 2        # views of the far state per hypothesis
    angle_steps: int = 24        # revolute values tried in [-pi, pi)
    slide_steps: int = 41        # prismatic values tried in [-1.5, 1.5] x part extent
    pivot_steps: int = 7         # then a pivot_steps^2 pivot grid over the part's extent about the best axis
    relabel: bool = True         # relabel Gaussians by multi-view colour consistency, then re-fit
    photo_views: int = 8         # views per non-reference state for the colour-consistency test
    photo_min_views: int = 3     # a hypothesis needs this many views in which the Gaussian is visible
    photo_margin: float = 0.03   # mean |colour error| a new label must beat the current one by
    photo_depth_tol: float = 0.01  # x scene extent: visible when no deeper than the rendered surface + tol
    photo_free_err: float = 0.25   # least error of a position in front of the rendered surface (empty space)
    chain: bool = True           # try each part as hanging from a touching movable part (lamp arms, handles)
    prune: bool = False          # parts the images show still join the base; touching parts one joint moves merge
    prune_margin: float = 0.01   # held still, a part's pixels may render this much worse and it is still static
    merge_iters: int = 100       # Adam steps re-fitting one joint to a candidate merged pair
    merge_margin: float = 0.02   # merged under one joint, two parts' pixels may render this much worse
    chain_touch: float = 0.03    # x scene extent: parts closer than this touch (candidate parents)
    chain_margin: float = 0.05   # the chained fit must lower the part's own pixel error by this fraction


@dataclass
class _Joint:
    """Learnable parameters of one part's joint (tensors with grad)."""

    label: int
    type: str
    axis: torch.Tensor    # (3,) unnormalised
    pivot: torch.Tensor   # (3,) revolute only (unused for prismatic)
    values: torch.Tensor  # (K,) angle (rad) or slide (m) per state; the reference entry is held at 0
    parent: int | None = None  # label of the part it hangs from (None: the static base)


def _motion(j: _Joint, k: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Joint j's rigid motion to state k: x' = R x + t, and its rotation as a quaternion (4,)."""
    u = j.axis / (j.axis.norm() + EPS)
    v = j.values[k]
    if j.type == "revolute":
        rq = torch.cat([torch.cos(0.5 * v).reshape(1), torch.sin(0.5 * v) * u])
        R = quat_to_rotmat(rq[None])[0]
        return R, j.pivot - R @ j.pivot, rq
    return torch.eye(3), v * u, torch.tensor([1.0, 0.0, 0.0, 0.0])


def _world_motions(joints: list[_Joint], k: int) -> dict[int, tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
    """label -> world motion (R, t, quat) of each part to state k: its own joint motion, then its parents'.
    A chained joint's axis and pivot are in the reference state's world frame, where every motion is the
    identity, so x' = T_parent(k) T_joint(k) x."""
    by_label = {j.label: j for j in joints}
    out: dict[int, tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = {}

    def world(j: _Joint, depth: int = 0):
        if j.label not in out:
            R, t, rq = _motion(j, k)
            if j.parent in by_label and depth < len(joints):  # depth: a cycle cannot recurse forever
                Rp, tp, qp = world(by_label[j.parent], depth + 1)
                R, t, rq = Rp @ R, Rp @ t + tp, quat_multiply(qp[None], rq[None])[0]
            out[j.label] = (R, t, rq)
        return out[j.label]
    for j in joints:
        world(j)
    return out


def _pose(ref: dict[str, torch.Tensor], groups: dict[int, torch.Tensor], joints: list[_Joint], k: int
          ) -> tuple[torch.Tensor, torch.Tensor]:
    """Means (N, 3) and quats (N, 4) of the reference Gaussians articulated to state k (``groups``: label ->
    indices of its Gaussians; everything else stays put)."""
    means, quats = ref["means"], ref["quats"]
    for label, (R, t, rq) in _world_motions(joints, k).items():
        idx = groups[label]
        means = means.index_put((idx,), means[idx] @ R.T + t)
        quats = quats.index_put((idx,), quat_multiply(rq.expand(len(idx), 4), quats[idx]))
    return means, quats


def _render(ref, groups, joints, k, cam: Camera, bg, backend: str) -> torch.Tensor:
    from pd2gs.render import rasterize

    f32 = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32)  # noqa: E731
    means, quats = _pose(ref, groups, joints, k)
    return rasterize(means, quats, ref["scales"], ref["colors"], ref["opacities"], f32(cam.K), f32(cam.w2c),
                     cam.width, cam.height, background=bg, backend=backend).rgb


def _init_joint(je: JointEstimate, label: int, state_ids: list[str], ref: int) -> _Joint:
    """Learnable copy of the centre-based estimate ``je`` (its own type; values relative to ``ref``)."""
    vals = np.array([je.values.get(s, 0.0) for s in state_ids], dtype=np.float64)
    t = lambda a: torch.tensor(np.asarray(a, dtype=np.float32), requires_grad=True)  # noqa: E731
    return _Joint(label, je.type, t(je.axis), t(je.origin), t(vals - vals[ref]))


def _principal_axes(P: np.ndarray) -> np.ndarray:
    """(3, 3) rows = principal directions of the point set P (n, 3), largest spread first."""
    return np.linalg.svd(P - P.mean(0), full_matrices=False)[2]


def _hypotheses(je: JointEstimate, P: np.ndarray, jtype: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """(axis, pivot) candidates of one type: the centre-based estimate's axis and the part's principal
    directions; for revolute joints pivots at the part's centroid, the estimate's pivot and the four
    corners of the part's extent in the plane orthogonal to the axis (hinges sit at part edges)."""
    axes = [np.asarray(je.axis, float)] + list(_principal_axes(P))
    uniq: list[np.ndarray] = []
    for a in axes:
        a = a / (np.linalg.norm(a) + EPS)
        if all(abs(float(a @ b)) < 0.985 for b in uniq):  # drop near-duplicates (< 10 deg apart)
            uniq.append(a)
    c = P.mean(0)
    if jtype == "prismatic":
        return [(a, c) for a in uniq]
    out = []
    for a in uniq:
        e = np.linalg.svd(np.eye(3) - np.outer(a, a))[0][:, :2]  # in-plane basis
        xy = (P - c) @ e
        lo, hi = np.percentile(xy, 2, axis=0), np.percentile(xy, 98, axis=0)
        pivots = [c, np.asarray(je.origin, float)] + [c + e @ np.array([x, y]) for x in (lo[0], hi[0])
                                                      for y in (lo[1], hi[1])]
        out += [(a, p) for p in pivots]
    return out


def _search(ref, groups, joints: list[_Joint], i: int, jtype: str, je: JointEstimate, P: np.ndarray, views: Views,
            far: int, ref_k: int, s: FitSettings, scale: float, bg, backend: str) -> tuple[_Joint, float]:
    """Best (axis, pivot, far-state value) of joint ``i`` of type ``jtype`` on a grid, others held as they
    are -> (joint with that start, its loss). Values of the other states are then searched on the same grid."""
    K = len(views)
    part_ext = float(np.linalg.norm(np.ptp(P, axis=0))) or scale
    grid = (np.linspace(-math.pi, math.pi, s.angle_steps, endpoint=False) if jtype == "revolute"
            else np.linspace(-1.5, 1.5, s.slide_steps) * part_ext)
    pick = lambda k: [views[k][int(j)] for j in  # noqa: E731
                      np.unique(np.linspace(0, len(views[k]) - 1, s.search_views + 2)[1:-1].round().astype(int))]
    f32 = lambda a: torch.tensor(np.asarray(a, dtype=np.float32))  # noqa: E731

    def loss_at(j: _Joint, k: int, v: float, vs) -> float:
        j.values.data[k] = float(v)
        trial = joints[:i] + [j] + joints[i + 1:]
        return float(np.mean([(_render(ref, groups, trial, k, cam, bg, backend)
                               - torch.as_tensor(rgb, dtype=torch.float32) / 255.0).abs().mean() for cam, rgb in vs]))

    best, best_loss = None, math.inf
    with torch.no_grad():
        vs = pick(far)
        for axis, pivot in _hypotheses(je, P, jtype):
            j = _Joint(joints[i].label, jtype, f32(axis), f32(pivot), torch.zeros(K), joints[i].parent)
            for v in grid:
                if v == 0.0:
                    continue
                loss = loss_at(j, far, v, vs)
                if loss < best_loss:
                    best, best_loss = (axis, pivot, v), loss
        axis, pivot, v = best
        if jtype == "revolute" and s.pivot_steps > 1:  # finer pivots (and nearby angles) about the chosen axis
            j = _Joint(joints[i].label, jtype, f32(axis), f32(pivot), torch.zeros(K), joints[i].parent)
            e = np.linalg.svd(np.eye(3) - np.outer(axis, axis))[0][:, :2]
            half = 0.5 * np.ptp((P - pivot) @ e, axis=0)
            offs = np.linspace(-1.0, 1.0, s.pivot_steps)
            dv = np.linspace(-1.0, 1.0, 7) * (math.pi / s.angle_steps * 2)
            for a in offs:
                for b in offs:
                    pv = pivot + e @ (np.array([a, b]) * half)
                    j.pivot = f32(pv)
                    for v2 in v + dv:
                        loss = loss_at(j, far, v2, vs)
                        if loss < best_loss:
                            best, best_loss = (axis, pv, v2), loss
            axis, pivot, v = best
        j = _Joint(joints[i].label, jtype, f32(axis), f32(pivot), torch.zeros(K), joints[i].parent)
        j.values.data[far] = float(v)
        for k in range(K):
            if k in (far, ref_k):
                continue
            vs = pick(k)
            j.values.data[k] = float(min(np.append(grid, 0.0), key=lambda x: loss_at(j, k, x, vs)))
    for t in (j.axis, j.pivot, j.values):
        t.requires_grad_(True)
    return j, best_loss


def _optimise(ref, groups, joints: list[_Joint], views: Views, ref_k: int, s: FitSettings, scale: float, bg,
              backend: str, rng: np.random.Generator, train: list[tuple[int, int]],
              learn: list[_Joint] | None = None) -> list[float]:
    """Adam on the parameters of ``learn`` (default: every joint) while all ``joints`` are rendered."""
    learn = joints if learn is None else learn
    params = []
    for j in learn:
        params.append({"params": [j.axis], "lr": s.lr_axis})
        params.append({"params": [j.values], "lr": (s.lr_angle if j.type == "revolute" else s.lr_slide * scale)})
        if j.type == "revolute":
            params.append({"params": [j.pivot], "lr": s.lr_pivot * scale})
    opt = torch.optim.Adam(params)
    lr0 = [g["lr"] for g in opt.param_groups]
    losses = []
    for it in range(s.iters):
        for g, l0 in zip(opt.param_groups, lr0):  # cosine decay to 10 %
            g["lr"] = l0 * (0.1 + 0.45 * (1 + math.cos(math.pi * it / max(1, s.iters))))
        k, i = train[int(rng.integers(len(train)))]
        cam, rgb = views[k][i]
        out = _render(ref, groups, joints, k, cam, bg, backend)
        loss = (out - torch.as_tensor(rgb, dtype=torch.float32) / 255.0).abs().mean()
        opt.zero_grad()
        loss.backward()
        for j in learn:
            if j.values.grad is not None:
                j.values.grad[ref_k] = 0.0
        opt.step()
        losses.append(float(loss.detach()))
    return losses


def _project(cam: Camera, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integer pixel (u, v) and camera depth z of world points X (n, 3) (OpenCV, pixel centres at integers)."""
    Xc = X @ cam.w2c[:3, :3].T + cam.w2c[:3, 3]
    z = Xc[:, 2]
    uv = (Xc @ np.asarray(cam.K).T)[:, :2] / np.maximum(z, 1e-9)[:, None]
    return np.round(uv[:, 0]).astype(int), np.round(uv[:, 1]).astype(int), z


def _photo_errors(ref, labels: np.ndarray, joints: list[_Joint], views: Views, ref_k: int, s: FitSettings,
                  scale: float, bg, backend: str) -> tuple[np.ndarray, np.ndarray]:
    """Mean |colour error| (N, 1 + P) of every Gaussian under every candidate motion (column 0 static, then
    ``joints``), inf with fewer than ``photo_min_views`` views of evidence; -> (errors, column labels)."""
    from pd2gs.render import rasterize

    f32 = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32)  # noqa: E731
    cols = np.array([0] + [j.label for j in joints])
    mu = ref["means"].numpy().astype(np.float64)
    colors = ref["colors"].numpy()
    n = len(labels)
    err = np.zeros((n, len(cols)))
    cnt = np.zeros((n, len(cols)))
    groups = {j.label: torch.as_tensor(np.flatnonzero(labels == j.label), dtype=torch.long) for j in joints}
    tol = s.photo_depth_tol * scale
    with torch.no_grad():
        for k in range(len(views)):
            if k == ref_k:
                continue
            world = _world_motions(joints, k)
            moved = [mu] + [(mu @ R.numpy().T.astype(np.float64) + t.numpy()) for R, t, _ in
                            (world[j.label] for j in joints)]
            means, quats = _pose(ref, groups, joints, k)
            pick = np.unique(np.linspace(0, len(views[k]) - 1, min(s.photo_views, len(views[k]))).round().astype(int))
            for i in pick:
                cam, rgb = views[k][int(i)]
                out = rasterize(means, quats, ref["scales"], ref["colors"], ref["opacities"], f32(cam.K),
                                f32(cam.w2c), cam.width, cam.height, background=bg, backend=backend)
                depth = np.where(out.alpha.numpy() > 0.5, out.depth.numpy(), np.inf)
                img = rgb.astype(np.float32) / 255.0
                for c, X in enumerate(moved):
                    u, v, z = _project(cam, X)
                    ok = (u >= 0) & (u < cam.width) & (v >= 0) & (v < cam.height) & (z > 0)
                    idx = np.flatnonzero(ok)
                    d = depth[v[idx], u[idx]]
                    vis = z[idx] <= d + tol
                    free = z[idx] < d - tol  # in front of the rendered surface: it would float in empty space
                    e = np.abs(colors[idx] - img[v[idx], u[idx]]).mean(1)
                    e = np.where(free, np.maximum(e, s.photo_free_err), e)
                    err[idx[vis], c] += e[vis]
                    cnt[idx[vis], c] += 1
    return np.where(cnt >= s.photo_min_views, err / np.maximum(cnt, 1), np.inf), cols


def _relabel_photo(ref, labels: np.ndarray, joints: list[_Joint], views: Views, ref_k: int, s: FitSettings,
                   scale: float, bg, backend: str) -> tuple[np.ndarray, dict]:
    """Multi-view colour consistency of each Gaussian under each part's motion -> new labels (N,).

    For every non-reference state k and a few of its views, the Gaussian centre moved by each candidate
    (static or joint p) is projected; where it is not hidden behind the surface rendered with the current
    labels (depth + tol), its colour is compared with the captured pixel, and a position in front of that
    surface (empty space) costs at least ``photo_free_err``. A Gaussian takes the candidate
    with the lowest mean |colour error| when that beats its current label by ``photo_margin`` with at least
    ``photo_min_views`` views of evidence for both. Hand-written: a render-and-compare test per Gaussian
    and hypothesis, which no library offers."""
    mean, cols = _photo_errors(ref, labels, joints, views, ref_k, s, scale, bg, backend)
    col_of = {int(lab): c for c, lab in enumerate(cols)}
    n = len(labels)
    cur = np.array([col_of.get(int(lab), 0) for lab in labels])
    best = mean.argmin(1)
    with np.errstate(invalid="ignore"):  # inf - inf where a Gaussian has no evidence at all
        gain = mean[np.arange(n), cur] - mean[np.arange(n), best]
    # a Gaussian hidden under its current label has no evidence against it: it keeps its label
    change = np.isfinite(mean[np.arange(n), best]) & np.isfinite(mean[np.arange(n), cur]) & (gain > s.photo_margin)
    new = np.where(change, best, cur)
    out_labels = np.where(np.isin(labels, cols), cols[new], labels)
    return out_labels, {"evidence_frac": float(np.mean(np.isfinite(mean).all(1)))}


def _part_losses(ref, groups, configs: list[list[_Joint]], label: int, views: Views, held: list[tuple[int, int]],
                 bg, backend: str) -> list[float]:
    """Mean |colour error| of each joint configuration over the pixels part ``label`` covers (its Gaussians
    rendered alone, alpha > 0.3) under any of the configurations, on the held-out views. A whole-image loss
    would hide a small part such as a handle."""
    return _footprint_losses(ref, [(groups, js) for js in configs], groups[label], views, held, bg, backend)


def _footprint_losses(ref, configs: list[tuple[dict[int, torch.Tensor], list[_Joint]]], idx: torch.Tensor,
                      views: Views, held: list[tuple[int, int]], bg, backend: str) -> list[float]:
    """As :func:`_part_losses` for configurations that also differ in their groups (label -> Gaussian
    indices); ``idx``: the Gaussians whose footprint is scored."""
    from pd2gs.render import rasterize

    err, cnt = np.zeros(len(configs)), 0
    with torch.no_grad():
        for k, i in held:
            cam, rgb = views[k][i]
            K, w2c = torch.as_tensor(cam.K, dtype=torch.float32), torch.as_tensor(cam.w2c, dtype=torch.float32)
            gt = torch.as_tensor(rgb, dtype=torch.float32) / 255.0
            outs, mask = [], torch.zeros(cam.height, cam.width, dtype=torch.bool)
            for groups, js in configs:
                means, quats = _pose(ref, groups, js, k)
                outs.append(rasterize(means, quats, ref["scales"], ref["colors"], ref["opacities"], K, w2c, cam.width,
                                      cam.height, background=bg, backend=backend).rgb)
                alone = rasterize(means[idx], quats[idx], ref["scales"][idx], ref["colors"][idx],
                                  ref["opacities"][idx], K, w2c, cam.width, cam.height, background=bg, backend=backend)
                mask |= alone.alpha.reshape(cam.height, cam.width) > 0.3
            cnt += int(mask.sum())
            for c, out in enumerate(outs):
                err[c] += float((out - gt).abs().mean(-1)[mask].sum())
    return list(err / max(cnt, 1))


def _prune_and_merge(ref, labels: np.ndarray, joints: list[_Joint], fld: StateField, r: int, views: Views,
                     held: list[tuple[int, int]], train: list[tuple[int, int]], s: FitSettings, scale: float, bg,
                     backend: str, rng: np.random.Generator) -> tuple[np.ndarray, list[_Joint], dict]:
    """Parts the images do not support (ours): a trained field that does not move a part rigidly splits it
    into several k-means clusters, and adds clusters that hardly move. On the held-out views, over the
    parts' own pixels:

    * a part whose pixels render no worse (``prune_margin``) with its joint held still joins the static base;
    * two touching parts of one joint type merge when one of their joints, re-fitted to both, moves both
      no worse (``merge_margin``), the pair that loses least first.

    It runs before the chain step, so every joint hangs from the base. Identical motions cannot be told
    apart, so equal drawers that always move together merge too. -> (labels, joints, {"pruned", "merged"}).
    """
    labels = np.asarray(labels).copy()
    joints = list(joints)
    diag: dict = {"pruned": [], "merged": []}
    groups = lambda: {j.label: torch.as_tensor(np.flatnonzero(labels == j.label), dtype=torch.long)  # noqa: E731
                      for j in joints}
    for j in list(joints):
        g = groups()
        still = _Joint(j.label, j.type, j.axis.detach(), j.pivot.detach(), torch.zeros_like(j.values), None)
        moved, held_still = _footprint_losses(ref, [(g, joints), (g, [still if x is j else x for x in joints])],
                                              g[j.label], views, held, bg, backend)
        if held_still <= moved * (1 + s.prune_margin):
            labels[labels == j.label] = 0
            joints.remove(j)
            diag["pruned"].append({"part": j.label, "moving": moved, "still": held_still})
    while True:
        near = _touching(fld, labels, [j.label for j in joints], r, s.chain_touch * scale)
        g = groups()
        best = None
        for a in joints:
            for b in joints:
                if a.label >= b.label or b.label not in near.get(a.label, []) or a.type != b.type:
                    continue
                both = torch.cat([g[a.label], g[b.label]])
                trials, fits = [(g, joints)], []
                for keep, drop in ((a, b), (b, a)):
                    gm = {k: v for k, v in g.items() if k != drop.label}
                    gm[keep.label] = both
                    fit = _Joint(keep.label, keep.type, keep.axis.detach().clone(), keep.pivot.detach().clone(),
                                 keep.values.detach().clone(), None)
                    for t in (fit.axis, fit.pivot, fit.values):
                        t.requires_grad_(True)
                    js = [fit if x is keep else x for x in joints if x is not drop]
                    _optimise(ref, gm, js, views, r, replace(s, iters=s.merge_iters), scale, bg, backend, rng, train,
                              learn=[fit])
                    trials.append((gm, js))
                    fits.append((keep, drop, fit))
                sep, *merged = _footprint_losses(ref, trials, both, views, held, bg, backend)
                c = int(np.argmin(merged))
                ratio = merged[c] / max(sep, 1e-12)
                if ratio <= 1 + s.merge_margin and (best is None or ratio < best[0]):
                    best = (ratio, *fits[c], sep, merged[c])
        if best is None:
            break
        _, keep, drop, fit, sep, merged = best
        labels[labels == drop.label] = keep.label
        joints = [fit if x is keep else x for x in joints if x is not drop]
        diag["merged"].append({"into": keep.label, "part": drop.label, "separate": sep, "merged": merged})
    return labels, joints, diag


def _ancestors(joints: list[_Joint], label: int) -> set[int]:
    by_label = {j.label: j for j in joints}
    out: set[int] = set()
    p = by_label[label].parent
    while p in by_label and p not in out:
        out.add(p)
        p = by_label[p].parent
    return out


def _touching(fld: StateField, labels: np.ndarray, parts: list[int], r: int, dist: float) -> dict[int, list[int]]:
    """label -> the other movable parts whose reference-state Gaussian centres come within ``dist`` of it."""
    from scipy.spatial import cKDTree

    trees = {p: cKDTree(fld.means[r][labels == p]) for p in parts if (labels == p).sum() >= 3}
    return {p: [q for q in trees if q != p and np.isfinite(trees[p].query(fld.means[r][labels == q],
                                                                           distance_upper_bound=dist)[0]).any()]
            for p in trees}


def _held_out_loss(ref, groups, joints, views: Views, held: list[tuple[int, int]], bg, backend: str) -> float:
    with torch.no_grad():
        return float(np.mean([(_render(ref, groups, joints, k, views[k][i][0], bg, backend)
                               - torch.as_tensor(views[k][i][1], dtype=torch.float32) / 255.0).abs().mean()
                              for k, i in held]))


def _to_estimate(j: _Joint, base: JointEstimate, state_ids: list[str], zero: int, end: str | None,
                 centroid: np.ndarray, diag: dict, frame: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> JointEstimate:
    """The submitted joint: values relative to state index ``zero``; ``frame`` = (R, t) maps the fit's
    reference-state world frame to the submitted one (a chained joint's parent pose at the start state)."""
    R, t = frame if frame is not None else (np.eye(3), np.zeros(3))
    u = R @ j.axis.detach().double().numpy()
    u = u / (np.linalg.norm(u) + EPS)
    centroid = R @ centroid + t
    vals = j.values.detach().double().numpy()
    vals = vals - vals[zero]
    if j.type == "revolute":  # states are captured in order and move < 180 deg apart: undo the grid's wrap
        vals = np.unwrap(vals)
        vals = vals - vals[zero]
        o = R @ j.pivot.detach().double().numpy() + t
        origin = o + u * float(u @ (centroid - o))  # the point on the axis closest to the part
    else:
        origin = centroid
    far = int(np.argmax(np.abs(vals)))
    sign_k = state_ids.index(end) if end in state_ids and end != state_ids[zero] else far
    if vals[sign_k] < 0:
        u, vals = -u, -vals
    return JointEstimate(j.type, u, origin, {s: float(v) for s, v in zip(state_ids, vals)}, "photometric",
                         base.type_paper, base.type_bic, {**base.diagnostics, **diag})


def _rezero(je: JointEstimate, state_ids: list[str], z: int) -> JointEstimate:
    """A centre-based estimate with its values relative to state index ``z`` (a world-frame joint's axis
    and pivot do not depend on the state they are read in)."""
    v0 = je.values.get(state_ids[z], 0.0)
    return replace(je, values={s: v - v0 for s, v in je.values.items()})


def fit_articulation(fld: StateField, labels: np.ndarray, joints: dict[int, JointEstimate], views: Views,
                     ref: str, end: str | None = None, settings: FitSettings | None = None,
                     background: tuple[float, float, float] | None = None, backend: str = "cpu", seed: int = 0,
                     start: str | None = None) -> tuple[dict[int, JointEstimate], np.ndarray, dict]:
    """Refine every part's joint (and, with ``settings.choose_type``, its type) photometrically.

    fld: the K-state field (its reference state ``ref`` supplies the Gaussians); labels (N,) part label
    per Gaussian (0 static); joints: label -> centre-based estimate (the start values); views[k] are
    training views of ``fld.state_ids[k]``; ``start`` (default ``ref``): the state whose world frame and
    values the returned joints use (a chained joint relative to its parent posed at ``start``).
    -> (label -> refined JointEstimate, labels (N,) after the soft relabelling (the input labels when
    ``settings.relabel`` is False), diagnostics).
    """
    s = settings or FitSettings()
    if not joints:
        return {}, np.asarray(labels), {}
    rng = np.random.default_rng(seed)
    r = fld.index(ref)
    z = fld.index(start) if start is not None else r  # the submitted joints' frame and zero
    f32 = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32)  # noqa: E731
    refg = {"means": f32(fld.means[r]), "quats": f32(fld.quats[r]), "scales": f32(fld.scales[r]),
            "colors": f32(fld.colors), "opacities": f32(fld.opacities)}
    groups = {p: torch.as_tensor(np.flatnonzero(labels == p), dtype=torch.long) for p in joints}
    bg = None if background is None else torch.tensor(background, dtype=torch.float32)
    pairs = [(k, i) for k in range(len(views)) for i in range(len(views[k]))]
    held = []
    for k in range(len(views)):  # evenly spaced held-out views per state
        n = len(views[k])
        held += [(k, int(i)) for i in np.unique(np.linspace(0, n - 1, min(s.eval_views, n)).round().astype(int))]
    train = [p for p in pairs if p not in set(held)] or pairs
    scale = float(np.linalg.norm(np.ptp(fld.means[r], axis=0))) or 1.0
    Qs = {p: fld.means[:, labels == p] for p in joints}
    cur = [_init_joint(je, p, fld.state_ids, r) for p, je in joints.items()]
    diag: dict = {"loss_start": _held_out_loss(refg, groups, cur, views, held, bg, backend), "seconds": {}}
    clock = time.perf_counter()

    def lap(name: str) -> None:
        nonlocal clock
        diag["seconds"][name] = round(time.perf_counter() - clock, 2)
        clock = time.perf_counter()
    other_type = {"revolute": "prismatic", "prismatic": "revolute"}
    opaque = np.asarray(fld.opacities).reshape(-1) > 0.1
    far = fld.index(end) if end in fld.state_ids and end != ref else max(
        (k for k in range(fld.k) if k != r), key=lambda k: float(np.abs(fld.means[k] - fld.means[r]).sum()))

    def search(i: int, p: int, jtype: str) -> tuple[_Joint, float]:
        sel = (labels == p) & opaque
        P = fld.means[r][sel] if sel.sum() >= 3 else Qs[p][r]
        return _search(refg, groups, cur, i, jtype, joints[p], P, views, far, r, s, scale, bg, backend)
    alts: dict[int, _Joint] = {}
    if s.search:
        diag["search"] = {}
        for i, (p, je) in enumerate(joints.items()):
            types = [je.type, other_type[je.type]] if s.choose_type else [je.type]
            found = {t: search(i, p, t) for t in types}
            if len(found) == 2:
                pick = ("revolute" if found["revolute"][1] < found["prismatic"][1] * (1 - s.type_margin)
                        else "prismatic")
                alts[p] = found[other_type[pick]][0]
            else:
                pick = je.type
            cur[i] = found[pick][0]
            diag["search"][p] = {t: v[1] for t, v in found.items()}
        lap("search")
    _optimise(refg, groups, cur, views, r, s, scale, bg, backend, rng, train)
    lap("fit")
    labels = np.asarray(labels).copy()
    if s.prune and cur:  # before the type trials and chains: those would only fit clusters that are not parts
        labels, cur, diag["prune"] = _prune_and_merge(refg, labels, cur, fld, r, views, held, train, s, scale, bg,
                                                      backend, rng)
        groups = {j.label: torch.as_tensor(np.flatnonzero(labels == j.label), dtype=torch.long) for j in cur}
        lap("prune")
    best = _held_out_loss(refg, groups, cur, views, held, bg, backend)
    diag["loss_fit"] = best
    diag["type_trials"] = {}
    if s.choose_type:
        for i, j in enumerate(list(cur)):
            other = other_type[j.type]
            alt = alts[j.label] if j.label in alts else search(i, j.label, other)[0]
            trial = cur[:i] + [alt] + cur[i + 1:]
            _optimise(refg, groups, trial, views, r, s, scale, bg, backend, rng, train, learn=[alt])
            loss = _held_out_loss(refg, groups, trial, views, held, bg, backend)
            rev_loss, pri_loss = (loss, best) if other == "revolute" else (best, loss)
            pick = "revolute" if rev_loss < pri_loss * (1 - s.type_margin) else "prismatic"
            diag["type_trials"][j.label] = {"revolute": rev_loss, "prismatic": pri_loss, "picked": pick}
            if pick == other:
                cur, best = trial, loss
    lap("type")
    if s.chain and len(cur) > 1:
        # a part hanging from another movable part (lamp arm, door handle) moves in the world by its parent's
        # motion and then its own, which no single world-frame joint reproduces: fit it as a child of each
        # touching part and keep the chain when that explains the part's own pixels clearly better
        diag["chain_trials"] = {}
        near = _touching(fld, labels, [j.label for j in cur], r, s.chain_touch * scale)
        for i in range(len(cur)):
            j = cur[i]
            for p in near.get(j.label, []):
                if p == j.parent or j.label in _ancestors(cur, p) | {p}:
                    continue
                child = _Joint(j.label, j.type, j.axis.detach().clone(), j.pivot.detach().clone(),
                               j.values.detach().clone(), parent=p)
                sel = (labels == j.label) & opaque
                P = fld.means[r][sel] if sel.sum() >= 3 else Qs[j.label][r]
                alt, _ = _search(refg, groups, cur[:i] + [child] + cur[i + 1:], i, j.type, joints[j.label], P, views,
                                 far, r, s, scale, bg, backend)
                trial = cur[:i] + [alt] + cur[i + 1:]
                _optimise(refg, groups, trial, views, r, s, scale, bg, backend, rng, train, learn=[alt])
                own, chained = _part_losses(refg, groups, [cur, trial], j.label, views, held, bg, backend)
                keep = chained < own * (1 - s.chain_margin)
                diag["chain_trials"][f"{j.label}<-{p}"] = {"own": own, "chained": chained, "kept": bool(keep)}
                if keep:
                    cur, j = trial, alt
        best = _held_out_loss(refg, groups, cur, views, held, bg, backend)
        lap("chain")
    if s.relabel:
        new, diag["relabel"] = _relabel_photo(refg, labels, cur, views, r, s, scale, bg, backend)
        diag["relabel_changed"] = int((new != labels).sum())
        labels = new
        groups = {p: torch.as_tensor(np.flatnonzero(labels == p), dtype=torch.long) for p in joints}
        _optimise(refg, groups, cur, views, r, s, scale, bg, backend, rng, train)
        best = _held_out_loss(refg, groups, cur, views, held, bg, backend)
        lap("relabel+refit")
    # a part keeps its centre-based joint when the images do not prefer the fitted one (e.g. a field whose
    # colours do not reproduce the captures): the fit never makes a joint photometrically worse
    centre = {p: _init_joint(je, p, fld.state_ids, r) for p, je in joints.items()}
    kept = []
    for i, j in enumerate(list(cur)):
        trial = cur[:i] + [centre[j.label]] + cur[i + 1:]
        loss = _held_out_loss(refg, groups, trial, views, held, bg, backend)
        if loss <= best:
            cur, best = trial, loss
            kept.append(j.label)
    diag["kept_centre_joints"] = kept
    with torch.no_grad():
        at_start = {p: (R.double().numpy(), t.double().numpy()) for p, (R, t, _) in _world_motions(cur, z).items()}
    out = {}
    for j in cur:
        if j.label in kept:
            out[j.label] = _rezero(joints[j.label], fld.state_ids, z)
            continue
        sel = labels == j.label
        P = fld.means[r][sel] if sel.sum() >= 3 else Qs[j.label][r]
        out[j.label] = _to_estimate(j, joints[j.label], fld.state_ids, z, end, P.mean(0),
                                    {"photometric_loss": best, "type_centres": joints[j.label].type,
                                     "parent": j.parent, "reference_state": fld.state_ids[r]},
                                    at_start.get(j.parent))
    diag["loss_final"] = best
    return out, labels, diag
