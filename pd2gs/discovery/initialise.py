"""Initialisation of discovery from stage 1 (a trained PD²GS field's per-state Gaussians).

Two steps, shared by both discovery modes:

* :func:`count_parts` -- how many movable parts (``cfg.counter``: our trajectory counter, rigid RANSAC,
  the paper's VLM, or the count given by meta.json);
* :func:`init_from_field` -- the first articulated model (mode ``articulated``): the static/dynamic split
  and rigid-motion clustering of the trajectories (:func:`.motion.coarse_labels`, which over- rather than
  under-segments), and per cluster the centre-based Kabsch joint (:func:`pd2gs.kinematics.estimate_joint`).

The canonical frame is the field at the reference state ``ref`` (so every joint value is 0 there, and the
fit's gauge ``ref_state`` is that state's index); colours and opacities are the field's shared ones, scales
and rotations the reference state's. Every movable body starts as a child of the base (a flat tree): which
part hangs on which is for model selection (:mod:`pd2gs.articulated.select`) to decide.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from pd2gs.articulated.model import ArticulatedGaussians, canonical_gaussians
from pd2gs.kinematics import JointFit, estimate_joint

from . import motion
from .config import DiscoveryConfig
from .counter import count_by_trajectories, count_rigid_motions, local_rigid_motions, sample_image_pairs, vlm_count
from .field import StateField, as_state_field


def count_parts(fld: StateField, dyn: np.ndarray, obj, states: list[str], cfg: DiscoveryConfig) -> tuple[int, dict]:
    """Number of movable parts by ``cfg.counter`` -> (n, diagnostics). ``dyn`` (N,) bool: the Gaussians that
    move (:func:`.motion.dynamic_mask`); ``obj`` (an ``rsart.load`` object) is read by the "given" counter
    (when ``cfg.given_count`` is None) and the "vlm" counter (its images) only."""
    if cfg.counter == "given":
        if cfg.given_count is None and obj is None:
            raise ValueError("counter='given' needs cfg.given_count or the object's meta.json")
        n = cfg.given_count if cfg.given_count is not None else len(obj.meta.parts) - 1
        return int(n), {"counter": "given"}
    if cfg.counter == "vlm":
        if obj is None:
            raise ValueError("counter='vlm' needs the object's images")
        pairs = sample_image_pairs(obj, states, cfg.vlm.n_pairs, cfg.vlm.seed)
        n, answers = vlm_count(pairs, cfg.vlm.url, cfg.vlm.model, cfg.vlm.api_key_env, cfg.vlm.timeout_s)
        return n, {"counter": "vlm", "answers": answers}
    if cfg.counter == "trajectory":
        sel = dyn & (np.asarray(fld.opacities).reshape(-1) >= cfg.count_min_opacity)
        if sel.sum() < 10:
            sel = dyn
        if sel.sum() == 0:
            return 0, {"counter": "trajectory", "n_voters": 0}
        n, diag = count_by_trajectories(local_rigid_motions(fld.means[:, sel], seed=cfg.seed), cfg.max_parts,
                                        cfg.min_silhouette, cfg.seed)
        return n, {"counter": "trajectory", "n_voters": int(sel.sum()), **diag}
    md = fld.means[:, dyn]
    if md.shape[1] < 3:
        return 0, {"counter": "motion", "support": []}
    dmax = float(motion.max_displacement(md).max())
    mc = count_rigid_motions(md, cfg.ransac_thresh_rel * dmax, cfg.min_part_frac, cfg.max_parts,
                             cfg.ransac_iters, cfg.seed)
    return mc.n, {"counter": "motion", "support": mc.support}


@dataclass
class InitResult:
    """The initial model and how it was obtained: ``labels`` (N,) 0 = base, 1..K; ``joints`` the K Kabsch
    estimates; ``ref_index`` the canonical state's index in ``state_ids``; ``count`` the counter's output
    (``n``) and the number of clusters the initialisation asked for (``clusters``);
    ``keep`` (N,) bool, the stage-1 Gaussians kept in the model (opacity at least ``min_opacity``)."""

    model: ArticulatedGaussians
    labels: np.ndarray
    joints: list[JointFit]
    state_ids: list[str]
    ref_index: int
    count: dict = field(default_factory=dict)
    keep: np.ndarray | None = None


def init_from_field(field_or_model: Any, state_ids: list[str], ref: str, end: str | None = None,
                    n_parts: int | None = None, cfg: DiscoveryConfig | None = None, obj=None,
                    confidence: float = 4.0, min_part: int = 10, min_opacity: float = 0.0) -> InitResult:
    """Build the first articulated model from stage 1.

    Args:
        field_or_model: a :class:`StateField` or a trained model with ``state_gaussians(state_id)``.
        state_ids: the training states, in the order the model's ``values`` rows will use.
        ref: the reference (canonical) state; ``end``: the state whose joint values are made positive.
        n_parts: the number of movable parts if known (that many clusters), else counted by ``cfg.counter``
            (:func:`count_parts`; "vlm" and a "given" count without ``cfg.given_count`` read ``obj``). A
            counted 1 (other than "given") starts as 2 clusters: model selection merges and prunes bodies
            but never adds one, so one part or two is then its choice on the held-out views rather than the
            counter's ``min_silhouette`` threshold (measured: docs/pd2gs-experiments.md, twenty-fourth entry).
        cfg: discovery settings for tau_mot, min_cluster_frac, kmeans_seed, joint_rule and the counter.
        obj: the ``rsart.load`` object (for the "vlm" and "given" counters only).
        confidence: initial ownership logit margin (see :func:`pd2gs.articulated.model.ownership_logits`).
        min_part: clusters with fewer Gaussians are given to the base.
        min_opacity: stage-1 Gaussians less opaque than this are left out of the model (they barely
            render; fewer Gaussians make every fit step cheaper).
    """
    cfg = cfg or DiscoveryConfig()
    fld: StateField = as_state_field(field_or_model, state_ids)
    r = fld.index(ref)
    count: dict = {}
    clusters = n_parts
    if n_parts is None:
        dyn = motion.dynamic_mask(fld.means, cfg.tau_mot)
        n_parts, count = count_parts(fld, dyn, obj, list(state_ids), cfg)
        # selection merges and prunes bodies but never adds one: a counted 1 starts as 2 clusters, so
        # whether the motion is one part or two is decided by the held-out views, not the counter's threshold
        clusters = n_parts if cfg.counter == "given" or n_parts < 1 else max(int(n_parts), 2)
    keep = np.asarray(fld.opacities).reshape(-1) >= min_opacity
    if keep.sum() < 10:
        keep = np.ones(fld.n, dtype=bool)
    fld = fld.select(keep)
    labels = np.zeros(fld.n, dtype=np.int64)
    if int(clusters) > 0:
        labels = motion.coarse_labels(fld.means, int(clusters), cfg.tau_mot, cfg.min_cluster_frac, cfg.kmeans_seed,
                                      cfg.kmeans_n_init, method="rigid")
    kept = [p for p in range(1, int(labels.max()) + 1) if (labels == p).sum() >= min_part]
    relabel = np.zeros(int(labels.max()) + 1, dtype=np.int64)
    relabel[kept] = np.arange(1, len(kept) + 1)
    labels = relabel[labels]
    joints = [estimate_joint(fld.means[:, labels == p], fld.state_ids, ref, end, cfg.joint_rule or "bic",
                             seed=cfg.kmeans_seed) for p in range(1, len(kept) + 1)]
    K = len(joints)
    values = np.array([[j.values[s] for j in joints] for s in fld.state_ids], dtype=np.float64).reshape(len(state_ids), K)
    gauss = canonical_gaussians(fld.means[r], fld.quats[r], fld.scales[r], np.clip(fld.colors, 0, 1),
                                fld.opacities)
    model = ArticulatedGaussians(gauss, [-1] + [0] * K, [j.type for j in joints],
                                 np.array([j.axis for j in joints]).reshape(K, 3),
                                 np.array([j.origin for j in joints]).reshape(K, 3), values,
                                 torch.from_numpy(labels), confidence=confidence)
    return InitResult(model, labels, joints, list(fld.state_ids), r, {"n": int(n_parts), "clusters": int(clusters),
                                                                      **count}, keep)
