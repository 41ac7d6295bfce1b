"""Coarse part segmentation from motion (paper Sec. 3.3): static vs dynamic, trajectory clustering.

All functions take Gaussian centres per state, ``means`` (K, N, 3) in the world frame, K >= 2.
"""
from __future__ import annotations

import numpy as np
from sklearn.cluster import KMeans

EPS = 1e-8


def max_displacement(means: np.ndarray) -> np.ndarray:
    """(N,) d_i = max over state pairs (j, k) of ||mu_i^(j) - mu_i^(k)||."""
    K = means.shape[0]
    d = np.zeros(means.shape[1])
    for j in range(K):
        for k in range(j + 1, K):
            d = np.maximum(d, np.linalg.norm(means[j] - means[k], axis=1))
    return d


def dynamic_mask(means: np.ndarray, tau_mot: float) -> np.ndarray:
    """(N,) bool: normalised displacement d_i / max_r d_r >= tau_mot (all False if nothing moves)."""
    d = max_displacement(means)
    dmax = float(d.max()) if d.size else 0.0
    if dmax <= 0:
        return np.zeros(means.shape[1], dtype=bool)
    return d / dmax >= tau_mot


def trajectory_descriptors(means: np.ndarray) -> np.ndarray:
    """(N, 4(K-1)) l2-normalised f_i = [unit(dmu^(k)), ||dmu^(k)||]_k over consecutive states."""
    steps = np.diff(means, axis=0)                      # (K-1, N, 3)
    lens = np.linalg.norm(steps, axis=2, keepdims=True)  # (K-1, N, 1)
    f = np.concatenate([steps / (lens + EPS), lens], axis=2)  # (K-1, N, 4)
    f = np.transpose(f, (1, 0, 2)).reshape(means.shape[1], -1)
    return f / (np.linalg.norm(f, axis=1, keepdims=True) + EPS)


def cluster_trajectories(means_dyn: np.ndarray, n_parts: int, min_frac: float = 0.02, seed: int = 0,
                         n_init: int = 10) -> np.ndarray:
    """k-means (k-means++) of the descriptors of the dynamic Gaussians -> (N_dyn,) labels 1..n.

    Clusters holding fewer than ``min_frac`` of the dynamic Gaussians are merged into the nearest
    remaining cluster (centre distance); labels are renumbered 1..n' by decreasing size.
    """
    n = means_dyn.shape[1]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    k = max(1, min(int(n_parts), n))
    f = trajectory_descriptors(means_dyn)
    km = KMeans(n_clusters=k, init="k-means++", n_init=n_init, random_state=seed).fit(f)
    lab = km.labels_.copy()
    centres = km.cluster_centers_
    while True:
        sizes = np.bincount(lab, minlength=k)
        alive = np.flatnonzero(sizes > 0)
        small = [c for c in alive if sizes[c] < min_frac * n]
        if not small or len(alive) <= 1:
            break
        c = min(small, key=lambda c: sizes[c])
        others = [o for o in alive if o != c]
        big = [o for o in others if sizes[o] >= min_frac * n] or others
        target = min(big, key=lambda o: np.linalg.norm(centres[o] - centres[c]))
        lab[lab == c] = target
    order = sorted(np.unique(lab), key=lambda c: -np.sum(lab == c))
    remap = {c: i + 1 for i, c in enumerate(order)}
    return np.array([remap[c] for c in lab], dtype=np.int64)


def _rigid_per_state(means: np.ndarray, members: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kabsch motions (K, 3, 3), (K, 3) from state 0 to every state of the ``members`` Gaussians."""
    from pd2gs.kinematics import kabsch

    K = means.shape[0]
    Rs, ts = np.tile(np.eye(3), (K, 1, 1)), np.zeros((K, 3))
    for k in range(1, K):
        Rs[k], ts[k] = kabsch(means[0][members], means[k][members])
    return Rs, ts


def cluster_rigid_motions(means_dyn: np.ndarray, n_parts: int, min_frac: float = 0.02, seed: int = 0,
                          n_init: int = 10, rounds: int = 5, trim: float = 0.7) -> np.ndarray:
    """Ours (not in the paper): (N_dyn,) labels 1..n of the dynamic Gaussians by rigid motion.

    The paper's descriptor mixes displacement length into the feature, so a rotating part (a door leaf,
    a lamp arm) splits by distance from its hinge. Here: k-means of local rigid motions
    (:func:`.counter.local_rigid_motions`: each Gaussian's neighbourhood Kabsch-fitted first -> last
    state) seeds n clusters; then, ``rounds`` times, each cluster's rigid motion to every state is fitted
    on its best-fitting ``trim`` fraction and every Gaussian joins the motion with the least RMS
    residual over the states. Chained parts move rigidly in the world too, so they separate the same way.
    Small clusters (< ``min_frac``) join their next-best motion; labels by decreasing size.
    ``means_dyn``: (K, N_dyn, 3), state 0 the reference.
    """
    from .counter import local_rigid_motions

    n = means_dyn.shape[1]
    k = max(1, min(int(n_parts), n))
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    if k == 1 or n < 10:
        return np.ones(n, dtype=np.int64)
    feats, idx = local_rigid_motions(means_dyn, seed=seed, return_index=True)
    km = KMeans(n_clusters=min(k, len(idx)), init="k-means++", n_init=n_init, random_state=seed)
    seed_lab = km.fit(feats).labels_
    members = [idx[seed_lab == c] for c in range(k) if (seed_lab == c).sum() >= 3]
    lab = np.zeros(n, dtype=np.int64)
    alive = np.ones(len(members), dtype=bool)
    for _ in range(max(1, rounds)):
        res = np.full((len(members), n), np.inf)
        for c, m in enumerate(members):
            if not alive[c]:
                continue
            Rs, ts = _rigid_per_state(means_dyn, m)
            d = np.linalg.norm(means_dyn - (np.einsum("kij,nj->kni", Rs, means_dyn[0]) + ts[:, None]), axis=2)
            res[c] = np.sqrt(np.mean(d ** 2, axis=0))
        lab = res.argmin(0)
        sizes = np.bincount(lab, minlength=len(members))
        small = alive & (sizes < min_frac * n)
        if small.any() and alive.sum() > 1:  # the smallest too-small cluster joins its members' next-best motion
            alive[int(np.flatnonzero(small)[np.argmin(sizes[small])])] = False
            res[~alive] = np.inf
            lab = res.argmin(0)
        new = []
        for c in range(len(members)):
            m = np.flatnonzero(lab == c)
            if len(m) >= 3:
                m = m[res[c, m] <= np.quantile(res[c, m], trim)]
            new.append(m if len(m) >= 3 else members[c])
        members = new
    order = sorted(np.unique(lab), key=lambda c: -np.sum(lab == c))
    remap = {c: i + 1 for i, c in enumerate(order)}
    return np.array([remap[c] for c in lab], dtype=np.int64)


def coarse_labels(means: np.ndarray, n_parts: int, tau_mot: float, min_frac: float = 0.02,
                  seed: int = 0, n_init: int = 10, method: str = "trajectory") -> np.ndarray:
    """(N,) part labels: 0 static, 1..n dynamic clusters (``method``: "trajectory", the paper's descriptor
    k-means, or "rigid", :func:`cluster_rigid_motions`)."""
    dyn = dynamic_mask(means, tau_mot)
    labels = np.zeros(means.shape[1], dtype=np.int64)
    if dyn.any() and n_parts > 0:
        cluster = cluster_rigid_motions if method == "rigid" else cluster_trajectories
        labels[dyn] = cluster(means[:, dyn], n_parts, min_frac, seed, n_init)
    return labels


def split_disconnected(points: np.ndarray, labels: np.ndarray, min_size: int, radius: float | None = None
                       ) -> np.ndarray:
    """Ours (not in the paper): split every dynamic cluster into spatially connected pieces.

    Parts that always move together (e.g. two drawers with equal limits in multi-part states) share one
    trajectory and one cluster; if they do not touch they are separate parts. points: (N, 3) centres in
    one state; labels: (N,) 0 static, 1..n. Pieces are connected within ``radius`` (default 3x the
    median nearest-neighbour distance of the dynamic centres); pieces smaller than ``min_size`` join the
    nearest kept piece of their cluster. -> relabelled (N,) 0, 1..n' (by decreasing size).
    """
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    out = labels.copy()
    dyn = np.flatnonzero(labels > 0)
    if len(dyn) < 2:
        return out
    if radius is None:
        d, _ = cKDTree(points[dyn]).query(points[dyn], k=2)
        radius = 3.0 * float(np.median(d[:, 1]))
    next_label = int(labels.max()) + 1
    for c in np.unique(labels[dyn]):
        idx = np.flatnonzero(labels == c)
        tree = cKDTree(points[idx])
        ncomp, comp = connected_components(tree.sparse_distance_matrix(tree, radius, output_type="coo_matrix"),
                                           directed=False)
        if ncomp == 1:
            continue
        sizes = np.bincount(comp)
        keep = [k for k in np.argsort(-sizes) if sizes[k] >= min_size] or [int(np.argmax(sizes))]
        kept = np.isin(comp, keep)
        if (~kept).any():  # small pieces join the nearest kept piece
            _, nn = cKDTree(points[idx[kept]]).query(points[idx[~kept]])
            comp[~kept] = comp[kept][nn]
        for k in keep[1:]:
            out[idx[comp == k]] = next_label
            next_label += 1
    order = sorted(np.unique(out[out > 0]), key=lambda c: -np.sum(out == c))
    remap = {c: i + 1 for i, c in enumerate(order)}
    return np.array([remap.get(c, 0) for c in out], dtype=np.int64)
