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
   far state's value on a grid, scored over one view of every state with the values linear in the
   state index (as the multi-part states are spaced); then a finer pivot grid about the best axis; then
   each other state's value near its linear value. Both joint types are searched.
2. Adam on all joints through the differentiable rasterizer.
3. type choice: the other type is fitted from its own search result; the lower held-out loss wins,
   revolute needing a relative margin (a revolute joint with a far pivot can imitate a slide).
   (A part whose centre-based joint renders no worse on held-out views keeps that joint.)
3b. chains: each part is also fitted as hanging from the largest larger movable part it touches (its motion is then
   its parent's followed by its own joint, whose axis and pivot are given at the reference state); the
   chain is kept when it lowers the error over the part's own pixels by ``chain_margin`` and a revolute
   child's axis passes within ``chain_touch`` of the parent's Gaussians (a hinge on it). The submitted
   joint of a chained part is then relative to its parent, as the benchmark's ground truth is.
3c. clusters that are not parts (:mod:`.consolidate`, right after step 2): a cluster whose own pixels
   render no worse moved by another cluster's joint, or held still, joins it; then two touching clusters
   of one type merge when one joint, re-fitted to both, renders them no worse.
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

from .consolidate import absorb_clusters, merge_touching
from .field import StateField
from .kinematics import EPS, JointEstimate
from .posing import (PartJoint, Views, footprint_losses, held_out_loss, pose, posed_parts, project, render_posed,
                     world_motions)


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
    search_views: int = 2        # views per state when each state's value is searched on the grid
    search_min_opacity: float = 0.1  # the grid search renders only Gaussians at least this opaque
    value_window: float = 0.25   # each state's value is searched within this fraction of the far value of the
    value_steps: int = 5         # ramp (linear in the state index), in 2 * value_steps + 1 steps
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
    part_ref: bool = True        # each part's Gaussians from the state that shows it best (else all from ``ref``)
    ref_views: int = 6           # views per state rendered to find that state
    absorb: bool = True          # clusters another cluster's joint (or standing still) explains as well join it
    absorb_margin: float = 0.02  # ... when their own pixels render at most this much worse (relative)
    merge_iters: int = 100       # then touching clusters of one type: Adam steps re-fitting one joint to both,
    merge_margin: float = 0.02   # which may render their pixels at most this much worse than their two joints
    chain_touch: float = 0.03    # x scene extent: parts closer than this touch (candidate parents)
    chain_margin: float = 0.05   # the chained fit must lower the part's own pixel error by this fraction


def _init_joint(je: JointEstimate, label: int, state_ids: list[str], ref: int) -> PartJoint:
    """Learnable copy of the centre-based estimate ``je`` (its own type; values relative to state ``ref``, whose
    Gaussians it moves)."""
    vals = np.array([je.values.get(s, 0.0) for s in state_ids], dtype=np.float64)
    t = lambda a: torch.tensor(np.asarray(a, dtype=np.float32), requires_grad=True)  # noqa: E731
    return PartJoint(label, je.type, t(je.axis), t(je.origin), t(vals - vals[ref]), ref=ref)


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


def _opaque_subset(ref: dict[str, torch.Tensor], groups: dict[int, torch.Tensor], min_opacity: float
                   ) -> tuple[dict[str, torch.Tensor], dict[int, torch.Tensor]]:
    """The Gaussians at least ``min_opacity`` opaque (ref, groups re-indexed): the grid search renders
    thousands of hypotheses, and a render costs per Gaussian, not per pixel (measured: 20k Gaussians
    29 ms, their 10.5k at least 0.1 opaque 14 ms)."""
    keep = ref["opacities"].reshape(-1) >= min_opacity
    new_index = torch.cumsum(keep.long(), 0) - 1
    sub = {k: (v[keep] if v.shape[0] == keep.shape[0] else v) for k, v in ref.items()}
    return sub, {lab: new_index[idx[keep[idx]]] for lab, idx in groups.items()}


def _search(ref, groups, joints: list[PartJoint], i: int, jtype: str, je: JointEstimate, P: np.ndarray, views: Views,
            s: FitSettings, scale: float, bg, backend: str) -> tuple[PartJoint, float]:
    """Best (axis, pivot, far-state value) of joint ``i`` of type ``jtype`` on a grid, others held as they
    are -> (joint with that start, its loss). The far state is the captured state furthest from the joint's
    reference state (states are in order); a hypothesis is scored on one view of every other state, with
    values interpolated linearly between the reference state (0) and the far one (as the multi-part states
    are spaced), so a part cannot explain the far state by leaving the picture when the states between
    still show it. Each state's value is then searched within ``value_window`` of its ramp value."""
    K = len(views)
    ref_k = joints[i].ref
    far = max(range(K), key=lambda k: (abs(k - ref_k), k))
    ref, groups = _opaque_subset(ref, groups, s.search_min_opacity)
    part_ext = float(np.linalg.norm(np.ptp(P, axis=0))) or scale
    grid = (np.linspace(-math.pi, math.pi, s.angle_steps, endpoint=False) if jtype == "revolute"
            else np.linspace(-1.5, 1.5, s.slide_steps) * part_ext)
    pick = lambda k: [views[k][int(j)] for j in  # noqa: E731
                      np.unique(np.linspace(0, len(views[k]) - 1, s.search_views + 2)[1:-1].round().astype(int))]
    f32 = lambda a: torch.tensor(np.asarray(a, dtype=np.float32))  # noqa: E731

    def loss_at(j: PartJoint, k: int, v: float, vs) -> float:
        j.values.data[k] = float(v)
        trial = joints[:i] + [j] + joints[i + 1:]
        return float(np.mean([(render_posed(ref, groups, trial, k, cam, bg, backend)
                               - torch.as_tensor(rgb, dtype=torch.float32) / 255.0).abs().mean() for cam, rgb in vs]))
    # one view of every non-reference state, spread around the object from state to state
    ramp = [(k, views[k][int((k + 0.5) / K * len(views[k]))]) for k in range(K) if k != ref_k]

    def loss_ramp(j: PartJoint, v: float) -> float:
        """Mean loss over the ``ramp`` views with the far state at ``v`` and values linear in the state index."""
        j.values.data[:] = torch.tensor([v * (k - ref_k) / (far - ref_k) for k in range(K)])
        trial = joints[:i] + [j] + joints[i + 1:]
        return float(np.mean([(render_posed(ref, groups, trial, k, cam, bg, backend)
                               - torch.as_tensor(rgb, dtype=torch.float32) / 255.0).abs().mean()
                              for k, (cam, rgb) in ramp]))

    best, best_loss = None, math.inf
    with torch.no_grad():
        for axis, pivot in _hypotheses(je, P, jtype):
            j = PartJoint(joints[i].label, jtype, f32(axis), f32(pivot), torch.zeros(K), joints[i].parent, ref_k)
            for v in grid:
                if v == 0.0:
                    continue
                loss = loss_ramp(j, v)
                if loss < best_loss:
                    best, best_loss = (axis, pivot, v), loss
        axis, pivot, v = best
        if jtype == "revolute" and s.pivot_steps > 1:  # finer pivots (and nearby angles) about the chosen axis
            j = PartJoint(joints[i].label, jtype, f32(axis), f32(pivot), torch.zeros(K), joints[i].parent, ref_k)
            e = np.linalg.svd(np.eye(3) - np.outer(axis, axis))[0][:, :2]
            half = 0.5 * np.ptp((P - pivot) @ e, axis=0)
            offs = np.linspace(-1.0, 1.0, s.pivot_steps)
            dv = np.linspace(-1.0, 1.0, 7) * (math.pi / s.angle_steps * 2)
            for a in offs:
                for b in offs:
                    pv = pivot + e @ (np.array([a, b]) * half)
                    j.pivot = f32(pv)
                    for v2 in v + dv:
                        loss = loss_ramp(j, v2)
                        if loss < best_loss:
                            best, best_loss = (axis, pv, v2), loss
            axis, pivot, v = best
        j = PartJoint(joints[i].label, jtype, f32(axis), f32(pivot), torch.zeros(K), joints[i].parent, ref_k)
        ramp_values = [v * (k - ref_k) / (far - ref_k) for k in range(K)]
        j.values.data[:] = torch.tensor(ramp_values)
        for k in range(K):  # each state near its ramp value: far from it a part can hide (inside a drawer's
            if k == ref_k:  # cabinet, behind a door), which no image penalises
                continue
            vs = pick(k)
            near = ramp_values[k] + np.linspace(-1.0, 1.0, 2 * s.value_steps + 1) * s.value_window * abs(v)
            j.values.data[k] = float(min(near, key=lambda x: loss_at(j, k, x, vs)))
    for t in (j.axis, j.pivot, j.values):
        t.requires_grad_(True)
    return j, best_loss


def _optimise(ref, groups, joints: list[PartJoint], views: Views, s: FitSettings, scale: float, bg, backend: str,
              rng: np.random.Generator, train: list[tuple[int, int]], learn: list[PartJoint] | None = None
              ) -> list[float]:
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
        out = render_posed(ref, groups, joints, k, cam, bg, backend)
        loss = (out - torch.as_tensor(rgb, dtype=torch.float32) / 255.0).abs().mean()
        opt.zero_grad()
        loss.backward()
        for j in learn:
            if j.values.grad is not None:
                j.values.grad[j.ref] = 0.0
        opt.step()
        losses.append(float(loss.detach()))
    return losses


def _photo_errors(ref, state_means: np.ndarray, labels: np.ndarray, joints: list[PartJoint], views: Views, r: int,
                  s: FitSettings, scale: float, bg, backend: str) -> tuple[np.ndarray, np.ndarray]:
    """Mean |colour error| (N, 1 + P) of every Gaussian under every candidate motion (column 0 static, then
    ``joints``), inf with fewer than ``photo_min_views`` views of evidence; -> (errors, column labels).
    Under a candidate, a Gaussian starts where the field puts it in that candidate's reference state
    (``state_means`` (K, N, 3); ``r`` for the static base), as it would after joining it; every captured
    state is evidence except the one where all candidates coincide (``r`` and every joint's reference)."""
    from pd2gs.render import rasterize

    f32 = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32)  # noqa: E731
    cols = np.array([0] + [j.label for j in joints])
    colors = ref["colors"].numpy()
    n = len(labels)
    err = np.zeros((n, len(cols)))
    cnt = np.zeros((n, len(cols)))
    groups = {j.label: torch.as_tensor(np.flatnonzero(labels == j.label), dtype=torch.long) for j in joints}
    tol = s.photo_depth_tol * scale
    with torch.no_grad():
        for k in range(len(views)):
            if k == r and all(j.ref == k for j in joints):
                continue  # every candidate puts every Gaussian where the field has it: no evidence, only dilution
            world = world_motions(joints, k)
            moved = [state_means[r]] + [(state_means[j.ref] @ world[j.label][0].numpy().T.astype(np.float64)
                                         + world[j.label][1].numpy()) for j in joints]
            means, quats = pose(ref, groups, joints, k)
            pick = np.unique(np.linspace(0, len(views[k]) - 1, min(s.photo_views, len(views[k]))).round().astype(int))
            for i in pick:
                cam, rgb = views[k][int(i)]
                out = rasterize(means, quats, ref["scales"], ref["colors"], ref["opacities"], f32(cam.K),
                                f32(cam.w2c), cam.width, cam.height, background=bg, backend=backend)
                depth = np.where(out.alpha.numpy() > 0.5, out.depth.numpy(), np.inf)
                img = rgb.astype(np.float32) / 255.0
                for c, X in enumerate(moved):
                    u, v, z = project(cam, X)
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


def _relabel_photo(ref, state_means: np.ndarray, labels: np.ndarray, joints: list[PartJoint], views: Views, r: int,
                   s: FitSettings, scale: float, bg, backend: str) -> tuple[np.ndarray, dict]:
    """Multi-view colour consistency of each Gaussian under each part's motion -> new labels (N,).

    For every state k and a few of its views, the Gaussian centre moved by each candidate
    (static or joint p) is projected; where it is not hidden behind the surface rendered with the current
    labels (depth + tol), its colour is compared with the captured pixel, and a position in front of that
    surface (empty space) costs at least ``photo_free_err``. A Gaussian takes the candidate
    with the lowest mean |colour error| when that beats its current label by ``photo_margin`` with at least
    ``photo_min_views`` views of evidence for both. Hand-written: a render-and-compare test per Gaussian
    and hypothesis, which no library offers."""
    mean, cols = _photo_errors(ref, state_means, labels, joints, views, r, s, scale, bg, backend)
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


def _ancestors(joints: list[PartJoint], label: int) -> set[int]:
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


def _axis_gap(j: PartJoint, P: np.ndarray) -> float:
    """Distance from the joint's axis line (through its pivot) to the nearest of the points P (n, 3)."""
    u = j.axis.detach().double().numpy()
    u = u / (np.linalg.norm(u) + EPS)
    d = P - j.pivot.detach().double().numpy()
    return float(np.min(np.linalg.norm(d - np.outer(d @ u, u), axis=1))) if len(P) else math.inf


def _to_estimate(j: PartJoint, base: JointEstimate, state_ids: list[str], zero: int, end: str | None,
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


def _reference_states(fld: StateField, labels: np.ndarray, parts: list[int], views: Views, n_views: int,
                      backend: str) -> dict[int, int]:
    """label -> index of the state in which the field shows that part best: the largest sum over its
    Gaussians of their largest rasterizer weight in ``n_views`` views of the state (a trained field places
    Gaussians well only where views of that state see them)."""
    from pd2gs.render import rasterize

    f32 = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32)  # noqa: E731
    seen = np.zeros((fld.k, len(labels)))
    with torch.no_grad():
        for k in range(fld.k):
            pick = np.unique(np.linspace(0, len(views[k]) - 1, min(n_views, len(views[k]))).round().astype(int))
            for i in pick:
                cam = views[k][int(i)][0]
                out = rasterize(f32(fld.means[k]), f32(fld.quats[k]), f32(fld.scales[k]), f32(fld.colors),
                                f32(fld.opacities), f32(cam.K), f32(cam.w2c), cam.width, cam.height, backend=backend,
                                return_max_weight=True)
                seen[k] = np.maximum(seen[k], out.max_weight.numpy())
    return {p: int(np.argmax(seen[:, labels == p].sum(1))) for p in parts}


def fit_articulation(fld: StateField, labels: np.ndarray, joints: dict[int, JointEstimate], views: Views,
                     ref: str, end: str | None = None, settings: FitSettings | None = None,
                     background: tuple[float, float, float] | None = None, backend: str = "cpu", seed: int = 0,
                     start: str | None = None) -> tuple[dict[int, JointEstimate], np.ndarray, dict]:
    """Refine every part's joint (and, with ``settings.choose_type``, its type) photometrically.

    fld: the K-state field; labels (N,) part label per Gaussian (0 static); joints: label -> centre-based
    estimate (the start values); views[k] are training views of ``fld.state_ids[k]``; ``ref``: the state
    whose Gaussians the static base (and, with ``settings.part_ref`` off, every part) is taken from; with
    ``settings.part_ref`` each part is taken from the state that shows it best (:func:`_reference_states`);
    ``start`` (default ``ref``): the state whose world frame and values the returned joints use (a chained
    joint relative to its parent posed at ``start``).
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
    stack = {"means": f32(fld.means), "quats": f32(fld.quats), "scales": f32(fld.scales),
             "colors": f32(fld.colors), "opacities": f32(fld.opacities)}
    labels = np.asarray(labels).copy()
    bg = None if background is None else torch.tensor(background, dtype=torch.float32)
    pairs = [(k, i) for k in range(len(views)) for i in range(len(views[k]))]
    held = []
    for k in range(len(views)):  # evenly spaced held-out views per state
        n = len(views[k])
        held += [(k, int(i)) for i in np.unique(np.linspace(0, n - 1, min(s.eval_views, n)).round().astype(int))]
    held_set = set(held)
    train = [p for p in pairs if p not in held_set] or pairs
    scale = float(np.linalg.norm(np.ptp(fld.means[r], axis=0))) or 1.0
    part_ref = (_reference_states(fld, labels, list(joints), views, s.ref_views, backend) if s.part_ref
                else {p: r for p in joints})
    cur = [_init_joint(je, p, fld.state_ids, part_ref[p]) for p, je in joints.items()]

    def posed(js: list[PartJoint]) -> tuple[dict, dict]:
        """(ref, groups) for the current labels and joints ``js``."""
        return posed_parts(stack, labels, js, r)

    def points(p: int, k: int) -> np.ndarray:
        """Centres (n, 3) of part p in state k (its opaque Gaussians when it has 3 or more)."""
        sel = labels == p
        return fld.means[k][sel & opaque] if (sel & opaque).sum() >= 3 else fld.means[k][sel]
    refg, groups = posed(cur)
    diag: dict = {"loss_start": held_out_loss(refg, groups, cur, views, held, bg, backend), "seconds": {},
                  "reference_states": {int(p): fld.state_ids[k] for p, k in part_ref.items()}}
    clock = time.perf_counter()

    def lap(name: str) -> None:
        nonlocal clock
        diag["seconds"][name] = round(time.perf_counter() - clock, 2)
        clock = time.perf_counter()
    other_type = {"revolute": "prismatic", "prismatic": "revolute"}
    opaque = np.asarray(fld.opacities).reshape(-1) > 0.1

    def search(i: int, p: int, jtype: str) -> tuple[PartJoint, float]:
        return _search(refg, groups, cur, i, jtype, joints[p], points(p, cur[i].ref), views, s, scale, bg, backend)
    alts: dict[int, PartJoint] = {}
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
    _optimise(refg, groups, cur, views, s, scale, bg, backend, rng, train)
    lap("fit")
    if s.absorb and cur:  # before the type trials and chains: those would only fit clusters that are not parts
        labels, cur, diag["absorb"] = absorb_clusters(stack, r, labels, cur, views, held, s.absorb_margin, bg, backend)

        def refit(ref_m, groups_m, js, j):
            _optimise(ref_m, groups_m, js, views, replace(s, iters=s.merge_iters), scale, bg, backend, rng, train,
                      learn=[j])
        labels, cur, diag["absorb"]["merged_refit"] = merge_touching(
            stack, r, labels, cur, lambda lab, parts: _touching(fld, lab, parts, r, s.chain_touch * scale), refit,
            views, held, s.merge_margin, bg, backend)
        refg, groups = posed(cur)
        lap("absorb")
    best = held_out_loss(refg, groups, cur, views, held, bg, backend)
    diag["loss_fit"] = best
    diag["type_trials"] = {}
    if s.choose_type:
        for i, j in enumerate(list(cur)):
            other = other_type[j.type]
            alt = alts[j.label] if j.label in alts else search(i, j.label, other)[0]
            trial = cur[:i] + [alt] + cur[i + 1:]
            _optimise(refg, groups, trial, views, s, scale, bg, backend, rng, train, learn=[alt])
            loss = held_out_loss(refg, groups, trial, views, held, bg, backend)
            rev_loss, pri_loss = (loss, best) if other == "revolute" else (best, loss)
            pick = "revolute" if rev_loss < pri_loss * (1 - s.type_margin) else "prismatic"
            diag["type_trials"][j.label] = {"revolute": rev_loss, "prismatic": pri_loss, "picked": pick}
            if pick == other:
                cur, best = trial, loss
    lap("type")
    if s.chain and len(cur) > 1:
        # a part hanging from another movable part (lamp arm, door handle) moves in the world by its parent's
        # motion and then its own, which no single world-frame joint reproduces: fit it as a child of each
        # touching part and keep the chain when that explains the part's own pixels clearly better. The child
        # is taken from its parent's reference state, where its axis and pivot are given.
        diag["chain_trials"] = {}
        near = _touching(fld, labels, [j.label for j in cur], r, s.chain_touch * scale)
        size = {q: int((labels == q).sum()) for q in near}
        for i in range(len(cur)):
            j = cur[i]
            # a part hangs from a larger one (handle on a leaf, holder on an arm): one trial per part, on the
            # largest larger part it touches, keeps the cost linear in the number of parts
            bigger = [p for p in near.get(j.label, []) if size.get(p, 0) > size.get(j.label, 0)]
            for p in sorted(bigger, key=lambda q: -size[q])[:1]:
                if p == j.parent or j.label in _ancestors(cur, p) | {p}:
                    continue
                parent = next(x for x in cur if x.label == p)
                child = PartJoint(j.label, j.type, j.axis.detach().clone(), j.pivot.detach().clone(),
                                  j.values.detach().clone() - float(j.values[parent.ref].detach()), p, parent.ref)
                tref, tgroups = posed(cur[:i] + [child] + cur[i + 1:])
                fits = {}  # the relative joint can be of the other type (a world "slide" that is a hinge on a hinge)
                for jtype in ([j.type, other_type[j.type]] if s.choose_type else [j.type]):
                    alt, _ = _search(tref, tgroups, cur[:i] + [child] + cur[i + 1:], i, jtype, joints[j.label],
                                     points(j.label, parent.ref), views, s, scale, bg, backend)
                    trial = cur[:i] + [alt] + cur[i + 1:]
                    _optimise(tref, tgroups, trial, views, s, scale, bg, backend, rng, train, learn=[alt])
                    fits[jtype] = (alt, trial)
                own, *losses = footprint_losses([(refg, groups, cur)] + [(tref, tgroups, t) for _, t in fits.values()],
                                                groups[j.label], views, held, bg, backend)
                by_type = dict(zip(fits, losses))
                pick = ("revolute" if "prismatic" not in by_type or ("revolute" in by_type and by_type["revolute"]
                                                                     < by_type["prismatic"] * (1 - s.type_margin))
                        else "prismatic")
                alt, trial = fits[pick]
                chained = by_type[pick]
                # a hinge on the parent: the child's axis passes through the parent's body (more freedom alone,
                # e.g. one fridge door "hanging" from the other, would also lower the error)
                gap = _axis_gap(alt, points(p, parent.ref)) if alt.type == "revolute" else 0.0
                keep = chained < own * (1 - s.chain_margin) and gap <= s.chain_touch * scale
                diag["chain_trials"][f"{j.label}<-{p}"] = {"own": own, "chained": by_type, "axis_gap": gap,
                                                           "kept": bool(keep)}
                if keep:
                    cur, j = trial, alt
                    refg, groups = tref, tgroups
        best = held_out_loss(refg, groups, cur, views, held, bg, backend)
        lap("chain")
    if s.relabel:
        new, diag["relabel"] = _relabel_photo(refg, fld.means, labels, cur, views, r, s, scale, bg, backend)
        diag["relabel_changed"] = int((new != labels).sum())
        labels = new
        refg, groups = posed(cur)
        _optimise(refg, groups, cur, views, s, scale, bg, backend, rng, train)
        best = held_out_loss(refg, groups, cur, views, held, bg, backend)
        lap("relabel+refit")
    # a part keeps its centre-based joint when the images do not prefer the fitted one (e.g. a field whose
    # colours do not reproduce the captures): the fit never makes a joint photometrically worse
    kept = []
    for i, j in enumerate(list(cur)):
        if j.parent is not None:  # a chained joint has no centre-based counterpart
            continue
        trial = cur[:i] + [_init_joint(joints[j.label], j.label, fld.state_ids, j.ref)] + cur[i + 1:]
        loss = held_out_loss(refg, groups, trial, views, held, bg, backend)
        if loss <= best:
            cur, best = trial, loss
            kept.append(j.label)
    diag["kept_centre_joints"] = kept
    with torch.no_grad():
        at_start = {p: (R.double().numpy(), t.double().numpy()) for p, (R, t, _) in world_motions(cur, z).items()}
    out = {}
    for j in cur:
        if j.label in kept:
            out[j.label] = _rezero(joints[j.label], fld.state_ids, z)
            continue
        out[j.label] = _to_estimate(j, joints[j.label], fld.state_ids, z, end, points(j.label, j.ref).mean(0),
                                    {"photometric_loss": best, "type_centres": joints[j.label].type,
                                     "parent": j.parent, "reference_state": fld.state_ids[j.ref]},
                                    at_start.get(j.parent))
    diag["loss_final"] = best
    return out, labels, diag
