"""Which motion clusters are parts (ours): clusters the images do not support join another part.

The trajectory clustering of a CPU-trained field returns clusters, not parts: a field that does not move
a part rigidly cuts it into several clusters (pieces of a drawer whose centres follow it only part of the
way, pieces of a thin temple) and adds clusters that hardly move. Two tests, after each cluster's joint is
fitted, both scored on the cluster's own pixels in held-out views:

* :func:`absorb_clusters` — a cluster that renders no worse (``margin``) moved by another cluster's
  joint, or standing still, joins that cluster (or the static base). No joint is re-fitted, so the test
  costs a few renders per cluster.
* :func:`merge_touching` — two touching clusters of one joint type merge when one joint, re-fitted to
  both, renders them no worse than their two joints (pieces of one part whose own fits drifted apart).

Frames and units as :mod:`.posing` (world frame, metres, radians; OpenCV cameras).
"""
from __future__ import annotations

from typing import Callable

import numpy as np
import torch

from .posing import PartJoint, Views, footprint_losses, posed_parts


def absorb_clusters(stack: dict[str, torch.Tensor], r: int, labels: np.ndarray, joints: list[PartJoint],
                    views: Views, held: list[tuple[int, int]], margin: float, bg, backend: str
                    ) -> tuple[np.ndarray, list[PartJoint], dict]:
    """Clusters that another motion explains as well join it, smallest cluster first.

    For each cluster c (fewest Gaussians first) the held-out views are rendered with c's Gaussians moved
    by its own joint, held still, and moved by every other cluster's joint (taken from that joint's
    reference state, as it would be after joining); over c's own pixels (its Gaussians rendered alone,
    alpha > 0.3, under any of those), the mean colour error of the best alternative may exceed its own
    joint's by at most ``margin`` (relative) for c to join it (label 0 = the static base, state ``r``).
    After each change the test starts again. Chained joints are not yet known here (every joint hangs
    from the base).

    stack: the multi-state field (see :func:`.posing.composite_ref`); labels (N,) 0 static, else a joint's
    label; views/held: captured views per state and the (state, view) pairs scored.
    -> (labels (N,), surviving joints, {"pruned": [...], "merged": [...], "kept": {label: last test}}).
    """
    labels = np.asarray(labels).copy()
    joints = list(joints)
    diag: dict = {"pruned": [], "merged": [], "kept": {}}

    def config(lab: np.ndarray, js: list[PartJoint]):
        return (*posed_parts(stack, lab, js, r), js)
    while joints:
        sizes = {j.label: int((labels == j.label).sum()) for j in joints}
        changed = False
        for j in sorted(joints, key=lambda j: (sizes[j.label], j.label)):
            others = [o for o in joints if o is not j]
            alts = [0] + [o.label for o in others]
            configs = [config(labels, joints)] + [config(np.where(labels == j.label, a, labels), others) for a in alts]
            idx = torch.as_tensor(np.flatnonzero(labels == j.label), dtype=torch.long)
            own, *alt = footprint_losses(configs, idx, views, held, bg, backend)
            c = int(np.argmin(alt))
            diag["kept"][j.label] = {"own": own, "alternative": alt[c], "best": alts[c]}
            if alt[c] <= own * (1.0 + margin):
                labels[labels == j.label] = alts[c]
                joints = others
                del diag["kept"][j.label]
                rec = {"part": j.label, "own": own, "alternative": alt[c]}
                if alts[c] == 0:
                    diag["pruned"].append(rec)
                else:
                    diag["merged"].append({**rec, "into": alts[c]})
                changed = True
                break
        if not changed:
            break
    return labels, joints, diag


def merge_touching(stack: dict[str, torch.Tensor], r: int, labels: np.ndarray, joints: list[PartJoint],
                   touching: Callable[[np.ndarray, list[int]], dict[int, list[int]]],
                   refit: Callable[[dict, dict, list[PartJoint], PartJoint], None],
                   views: Views, held: list[tuple[int, int]], margin: float, bg, backend: str
                   ) -> tuple[np.ndarray, list[PartJoint], list[dict]]:
    """Touching clusters of one joint type that one joint moves as well merge, the best pair first.

    For every pair (a, b) with b in ``touching(labels, parts)[a]``, the larger cluster's joint is copied,
    re-fitted to the union by ``refit(ref, groups, joints, joint)`` (in place; Adam in :mod:`.articulate`),
    and the union's pixels (held-out views) are scored under the merged and the separate joints. The pair whose merged
    error exceeds its separate error by the least, at most by ``margin`` (relative), merges; repeated
    until no pair passes. -> (labels (N,), joints, [{"into", "part", "separate", "merged"}]).
    """
    labels = np.asarray(labels).copy()
    joints = list(joints)
    done: list[dict] = []

    def config(lab: np.ndarray, js: list[PartJoint]):
        return (*posed_parts(stack, lab, js, r), js)
    while True:
        sizes = {j.label: int((labels == j.label).sum()) for j in joints}
        near = touching(labels, [j.label for j in joints])
        best = None
        separate = config(labels, joints)
        for a in joints:
            for b in joints:
                if a.label >= b.label or b.label not in near.get(a.label, []) or a.type != b.type:
                    continue
                keep, drop = (a, b) if sizes[a.label] >= sizes[b.label] else (b, a)
                fit = PartJoint(keep.label, keep.type, keep.axis.detach().clone(), keep.pivot.detach().clone(),
                                keep.values.detach().clone(), keep.parent, keep.ref)
                for t in (fit.axis, fit.pivot, fit.values):
                    t.requires_grad_(True)
                merged_labels = np.where(labels == drop.label, keep.label, labels)
                js = [fit if x is keep else x for x in joints if x is not drop]
                merged = config(merged_labels, js)
                refit(merged[0], merged[1], js, fit)
                both = torch.as_tensor(np.flatnonzero(merged_labels == keep.label), dtype=torch.long)
                sep, mer = footprint_losses([separate, merged], both, views, held, bg, backend)
                ratio = mer / max(sep, 1e-12)
                if ratio <= 1.0 + margin and (best is None or ratio < best[0]):
                    best = (ratio, keep, drop, fit, sep, mer)
        if best is None:
            return labels, joints, done
        _, keep, drop, fit, sep, mer = best
        labels[labels == drop.label] = keep.label
        joints = [fit if x is keep else x for x in joints if x is not drop]
        done.append({"into": keep.label, "part": drop.label, "separate": sep, "merged": mer})
