"""Boundary-aware refinement (paper Sec. 3.4, App. A.1): SAGD-style splitting of Gaussians that leave
their part's mask, multi-view label voting, and (optionally) a short fine-tune of the children.

Prompts and mask providers live in :mod:`pd2gs.discovery.masks` (re-exported here).

Geometry of one split (scene units, world frame, one state): e = unit major axis of the Gaussian
(largest std-dev sigma), extent s = 2 * axis_sigma * sigma, lambda = fraction of the projected major
axis (from its in-mask end A towards B) inside the mask:
    part child  mu + (1 - lambda)/2 * s * e', std-dev lambda * sigma
    bg child    mu - lambda/2 * s * e',       std-dev (1 - lambda) * sigma
with e' = +e or -e, whichever points towards A. Colour, opacity and the other axes are inherited.
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from rsart.camera import Camera

from .field import StateField
from .masks import (GrabCutProvider, OracleProvider, SamProvider, farthest_point_sampling, make_provider,
                    sample_prompts, visibility_sets)

__all__ = ["GrabCutProvider", "OracleProvider", "SamProvider", "farthest_point_sampling", "make_provider",
           "sample_prompts", "visibility_sets", "rotmats", "project_ellipse", "in_mask_ratio", "split_children",
           "SplitResult", "boundary_split", "vote_labels"]


def rotmats(quats: np.ndarray) -> np.ndarray:
    """(N, 4) (w, x, y, z) -> (N, 3, 3)."""
    q = np.asarray(quats, dtype=np.float64).reshape(-1, 4)
    return Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()


def project_ellipse(mean: np.ndarray, R: np.ndarray, scale: np.ndarray, cam: Camera, axis_sigma: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """EWA projection of one Gaussian: -> (centre (2,), end A (2,), end B (2,)) of the 2D major axis at
    +-axis_sigma std-devs. Sigma' = J W Sigma W^T J^T (App. A.1)."""
    w2c = cam.w2c
    pc = w2c[:3, :3] @ mean + w2c[:3, 3]
    fx, fy = cam.intrinsics.fx, cam.intrinsics.fy
    z = pc[2]
    J = np.array([[fx / z, 0, -fx * pc[0] / z ** 2], [0, fy / z, -fy * pc[1] / z ** 2]])
    S = R @ np.diag(scale ** 2) @ R.T
    S2 = J @ w2c[:3, :3] @ S @ w2c[:3, :3].T @ J.T
    ev, V = np.linalg.eigh(S2)
    c = np.array([fx * pc[0] / z + cam.intrinsics.cx, fy * pc[1] / z + cam.intrinsics.cy])
    d = V[:, 1] * axis_sigma * np.sqrt(max(ev[1], 0.0))
    return c, c + d, c - d


def _inside(mask: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(M,) bool: pixels (rounded) of (M, 2) uv inside the image and the mask."""
    uv = np.atleast_2d(uv)
    u = np.rint(uv[:, 0]).astype(np.int64)
    v = np.rint(uv[:, 1]).astype(np.int64)
    ok = (u >= 0) & (v >= 0) & (u < mask.shape[1]) & (v < mask.shape[0])
    out = np.zeros(len(uv), dtype=bool)
    out[ok] = mask[v[ok], u[ok]]
    return out


def in_mask_ratio(mask: np.ndarray, A: np.ndarray, B: np.ndarray, samples: int = 64) -> float:
    """lambda = |O A| / |A B|: the fraction of segment A->B inside ``mask`` before its first exit O
    (A is assumed inside). Sampled at ``samples`` + 1 points."""
    t = np.linspace(0.0, 1.0, samples + 1)
    ins = _inside(mask, A[None] + t[:, None] * (B - A)[None])
    out = np.flatnonzero(~ins)
    if out.size == 0:
        return 1.0
    j = int(out[0])
    return 0.0 if j == 0 else float((t[j - 1] + t[j]) / 2)


def split_children(mu: np.ndarray, R: np.ndarray, scale: np.ndarray, lam: float, axis_sigma: float,
                   towards: float = 1.0) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Split one Gaussian (mean (3,), rotation (3,3), std-devs (3,)) along its major axis at ``lam``.

    ``towards`` = +1 when the part (in-mask) side is along +e, -1 along -e.
    -> ((mu_part, scale_part), (mu_bg, scale_bg)).
    """
    j = int(np.argmax(scale))
    e = R[:, j] * np.sign(towards)
    s = 2.0 * axis_sigma * scale[j]
    sp, sb = scale.copy(), scale.copy()
    sp[j], sb[j] = lam * scale[j], (1.0 - lam) * scale[j]
    return (mu + (1 - lam) / 2 * s * e, sp), (mu - lam / 2 * s * e, sb)


@dataclass
class SplitResult:
    """The refined field, its labels (N',), the indices of the new children, and counts."""

    field: StateField
    labels: np.ndarray
    children: np.ndarray
    n_candidates: int
    n_splits: int
    stats: dict = field(default_factory=dict)


def nearest_views(means: np.ndarray, cams: list[Camera], visible: np.ndarray | None = None, k: int = 1
                  ) -> np.ndarray:
    """(N, k) indices of the k nearest cameras (centre distance) seeing each point in frame (and, when
    ``visible`` (V, N) is given, with a non-zero rasterizer weight); -1 where none."""
    V = len(cams)
    dist = np.full((V, len(means)), np.inf)
    for v, cam in enumerate(cams):
        uv, z = cam.project(means)
        ok = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] <= cam.width - 1) & (uv[:, 1] <= cam.height - 1)
        if visible is not None:
            ok &= visible[v]
        dist[v, ok] = np.linalg.norm(means[ok] - cam.center, axis=1)
    order = np.argsort(dist, axis=0)[:k].T
    bad = np.take_along_axis(dist.T, order, axis=1) == np.inf
    order[bad] = -1
    return order


def _seen(cam: Camera, p: np.ndarray, depth: np.ndarray | None, tol: float) -> tuple[int, int] | None:
    """Pixel (row, col) of point p (3,) in ``cam`` when in frame and not behind the rendered surface
    (z <= depth + tol where depth > 0; no test without a depth map), else None."""
    uv, z = cam.project(p[None])
    u, r = int(np.rint(uv[0, 0])), int(np.rint(uv[0, 1]))
    if z[0] <= 0 or not (0 <= u < cam.width and 0 <= r < cam.height):
        return None
    if depth is not None and depth[r, u] > 0 and z[0] > depth[r, u] + tol:
        return None
    return r, u


def vote_labels(means: np.ndarray, cams: list[Camera], label_maps: list[np.ndarray], k: int,
                default: np.ndarray, depths: list[np.ndarray] | None = None, tol: float = 0.0) -> np.ndarray:
    """Majority label over the k nearest views in which each point is visible (depth test against the
    rendered depth when ``depths`` is given) of the label map (-1 = no mask, ignored); ``default`` (N,)
    where no view votes."""
    nv = nearest_views(means, cams, k=len(cams))
    out = default.copy()
    for i in range(len(means)):
        votes = []
        for v in nv[i]:
            if v < 0 or len(votes) >= k:
                continue
            px = _seen(cams[v], means[i], None if depths is None else depths[v], tol)
            if px is None:
                continue
            lab = int(label_maps[v][px])
            if lab >= 0:
                votes.append(lab)
        if votes:
            out[i] = np.bincount(votes).argmax()
    return out


def boundary_split(fld: StateField, labels: np.ndarray, ref: int, cams: list[Camera],
                   part_masks: list[dict[int, np.ndarray]], visible: np.ndarray | None = None,
                   axis_sigma: float = 2.0, min_scale: float = 2e-3, max_splits: int = 20000,
                   vote_views: int = 5, depths: list[np.ndarray] | None = None, depth_tol: float = 0.0,
                   edge_px: float = 1.0) -> SplitResult:
    """Split every Gaussian whose projected major axis leaves its part's mask in its nearest view.

    fld: the K state fields; labels (N,); ref: state index the masks belong to; cams: the V views of that
    state; part_masks[v][p]: bool (H, W) mask of part p in view v; visible: (V, N) bool or None.
    Largest projected error (pixels of the axis outside the mask) first; children re-queued until they
    lie in one mask or their std-dev falls below ``min_scale``; finally every child's label is voted
    over its ``vote_views`` nearest views where it is not occluded (``depths``: rendered depth per view,
    ``depth_tol`` its tolerance). An axis end must leave the mask by more than ``edge_px`` pixels. Splits are applied in every state in the Gaussian's own frame.
    """
    K, N = fld.k, fld.n
    cap = N + 2 * max_splits
    means = np.zeros((K, cap, 3)); means[:, :N] = fld.means
    quats = np.zeros((K, cap, 4)); quats[:, :N] = fld.quats
    scales = np.ones((K, cap, 3)); scales[:, :N] = fld.scales
    colors = np.zeros((cap, 3)); colors[:N] = fld.colors
    opac = np.zeros(cap); opac[:N] = fld.opacities
    lab = np.zeros(cap, dtype=np.int64); lab[:N] = labels
    alive = np.zeros(cap, dtype=bool); alive[:N] = True
    V = len(cams)
    label_maps = []
    for v in range(V):
        lm = np.full((cams[v].height, cams[v].width), -1, dtype=np.int64)
        for p, m in sorted(part_masks[v].items()):
            lm[m] = p
        label_maps.append(lm)
    Rref = rotmats(fld.quats[ref])
    nearest = nearest_views(fld.means[ref], cams, visible)[:, 0]

    def assess(i: int, R: np.ndarray, v: int):
        """-> (error px, lambda, towards) when Gaussian i is a boundary candidate in view v, else None."""
        m = part_masks[v].get(int(lab[i]))
        if m is None:
            return None
        c, A2, B2 = project_ellipse(means[ref, i], R, scales[ref, i], cams[v], axis_sigma)
        ends = np.stack([A2, B2])
        half = np.linalg.norm(A2 - c)
        if half > edge_px:  # ends pulled edge_px towards the centre: pixel rounding is not a boundary
            ends = c + (ends - c) * (1 - edge_px / half)
        ins = _inside(m, ends)
        if ins.all() or not _inside(m, c)[0] and not ins.any():
            return None
        j = int(np.argmax(scales[ref, i]))
        e = R[:, j] * axis_sigma * scales[ref, i, j]
        uv, z = cams[v].project(np.stack([means[ref, i] + e, means[ref, i] - e]))
        if (z <= 0).any():
            return None
        pin = _inside(m, uv)
        if not pin.any():
            return None
        towards = 1.0 if pin[0] else -1.0
        A, B = (uv[0], uv[1]) if pin[0] else (uv[1], uv[0])
        lam = in_mask_ratio(m, A, B)
        if lam <= 0.0 or (1 - lam) * float(np.linalg.norm(B - A)) <= edge_px:
            return None
        return (1 - lam) * float(np.linalg.norm(B - A)), lam, towards

    heap: list[tuple[float, int, int]] = []
    rot_cache: dict[int, np.ndarray] = {}
    n_cand = 0
    for i in range(N):
        v = int(nearest[i])
        if v < 0:
            continue
        a = assess(i, Rref[i], v)
        if a is not None:
            n_cand += 1
            heapq.heappush(heap, (-a[0], i, v))
            rot_cache[i] = Rref[i]
    n = N
    n_splits = 0
    children = []
    while heap and n_splits < max_splits:
        _, i, v = heapq.heappop(heap)
        R = rot_cache[i]
        a = assess(i, R, v)
        if a is None or scales[ref, i].max() < min_scale:
            continue
        _, lam, towards = a
        for k in range(K):
            Rk = R if k == ref else rotmats(quats[k, i])[0]
            (mp, sp), (mb, sb) = split_children(means[k, i], Rk, scales[k, i], lam, axis_sigma, towards)
            means[k, n], scales[k, n] = mp, sp
            means[k, n + 1], scales[k, n + 1] = mb, sb
            quats[k, n] = quats[k, n + 1] = quats[k, i]
        colors[n] = colors[n + 1] = colors[i]
        opac[n] = opac[n + 1] = opac[i]
        lab[n] = lab[i]
        lab[n + 1] = vote_labels(means[ref, n + 1:n + 2], cams, label_maps, 1, lab[i:i + 1], depths, depth_tol)[0]
        alive[i] = False
        alive[n] = alive[n + 1] = True
        children += [n, n + 1]
        for c in (n, n + 1):
            rot_cache[c] = R
            cv = nearest_views(means[ref, c:c + 1], cams)[0, 0]
            if cv >= 0 and scales[ref, c].max() >= min_scale:
                ac = assess(c, R, cv)
                if ac is not None:
                    heapq.heappush(heap, (-ac[0], c, cv))
        n += 2
        n_splits += 1
    ch = np.array([c for c in children if alive[c]], dtype=np.int64)
    if ch.size:
        lab[ch] = vote_labels(means[ref, ch], cams, label_maps, vote_views, lab[ch], depths, depth_tol)
    keep = np.flatnonzero(alive[:n])
    new_index = -np.ones(n, dtype=np.int64)
    new_index[keep] = np.arange(len(keep))
    out = StateField(list(fld.state_ids), means[:, keep], quats[:, keep], scales[:, keep], colors[keep],
                     opac[keep], lab[keep], fld.deform, dict(fld.extra))
    return SplitResult(out, lab[keep], new_index[ch], n_cand, n_splits,
                       {"n_before": N, "n_after": len(keep)})
