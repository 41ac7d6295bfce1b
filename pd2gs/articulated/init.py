"""Initialise an articulated model from stage 1 (a trained PD²GS field's per-state Gaussians).

Reuses discovery's steps, unchanged: the motion counter (:func:`pd2gs.discovery.pipeline.count_parts`,
unless the count is given), the static/dynamic split and rigid-motion clustering of the trajectories
(:func:`pd2gs.discovery.motion.coarse_labels`, which over- rather than under-segments), and per cluster the
Kabsch joint (:func:`pd2gs.discovery.kinematics.estimate_joint`).

The canonical frame is the field at the reference state ``ref`` (so every joint value is 0 there, and
the fit's gauge ``ref_state`` is that state's index); colours and opacities are the field's shared ones.
Every movable body starts as a child of the base (a flat tree): which part hangs on which is for model
selection to decide.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from pd2gs.discovery import motion
from pd2gs.discovery.config import DiscoveryConfig
from pd2gs.discovery.field import StateField, as_state_field
from pd2gs.discovery.kinematics import JointEstimate, estimate_joint

from .model import ArticulatedGaussians, canonical_gaussians


@dataclass
class InitResult:
    """The initial model and how it was obtained: ``labels`` (N,) 0 = base, 1..K; ``joints`` the K Kabsch
    estimates; ``ref_index`` the canonical state's index in ``state_ids``; ``count`` the counter's output."""

    model: ArticulatedGaussians
    labels: np.ndarray
    joints: list[JointEstimate]
    state_ids: list[str]
    ref_index: int
    count: dict = field(default_factory=dict)


def init_from_field(field_or_model: Any, state_ids: list[str], ref: str, end: str | None = None,
                    n_parts: int | None = None, cfg: DiscoveryConfig | None = None,
                    confidence: float = 4.0, min_part: int = 10) -> InitResult:
    """Build the first articulated model from stage 1.

    Args:
        field_or_model: a :class:`StateField` or a trained model with ``state_gaussians(state_id)``.
        state_ids: the training states, in the order the model's ``values`` rows will use.
        ref: the reference (canonical) state; ``end``: the state whose joint values are made positive.
        n_parts: the number of movable parts if known (the ``given`` counter), else counted by
            ``cfg.counter`` ("trajectory" or "motion"; "vlm" needs an object and is not supported here).
        cfg: discovery settings for tau_mot, min_cluster_frac, kmeans_seed, joint_rule and the counter.
        confidence: initial ownership logit margin (see :func:`.model.ownership_logits`).
        min_part: clusters with fewer Gaussians are given to the base.
    """
    from pd2gs.discovery.pipeline import count_parts

    cfg = cfg or DiscoveryConfig()
    fld: StateField = as_state_field(field_or_model, state_ids)
    r = fld.index(ref)
    count: dict = {}
    if n_parts is None:
        if cfg.counter not in ("trajectory", "motion"):
            raise ValueError(f"counter={cfg.counter!r}: init_from_field counts with 'trajectory' or 'motion', "
                             "or pass n_parts")
        dyn = motion.dynamic_mask(fld.means, cfg.tau_mot)
        n_parts, count = count_parts(fld, dyn, None, list(state_ids), cfg)
    labels = motion.coarse_labels(fld.means, int(n_parts), cfg.tau_mot, cfg.min_cluster_frac, cfg.kmeans_seed,
                                  cfg.kmeans_n_init, method="rigid")
    kept = [p for p in range(1, int(labels.max()) + 1) if (labels == p).sum() >= min_part]
    relabel = np.zeros(int(labels.max()) + 1, dtype=np.int64)
    relabel[kept] = np.arange(1, len(kept) + 1)
    labels = relabel[labels]
    joints = [estimate_joint(fld.means[:, labels == p], fld.state_ids, ref, end, cfg.joint_rule,
                             seed=cfg.kmeans_seed) for p in range(1, len(kept) + 1)]
    K = len(joints)
    values = np.array([[j.values[s] for j in joints] for s in fld.state_ids], dtype=np.float64).reshape(len(state_ids), K)
    gauss = canonical_gaussians(fld.means[r], fld.quats[r], fld.scales[r], np.clip(fld.colors, 0, 1),
                                fld.opacities)
    model = ArticulatedGaussians(gauss, [-1] + [0] * K, [j.type for j in joints],
                                 np.array([j.axis for j in joints]).reshape(K, 3),
                                 np.array([j.origin for j in joints]).reshape(K, 3), values,
                                 torch.from_numpy(labels), confidence=confidence)
    return InitResult(model, labels, joints, list(fld.state_ids), r, count)
