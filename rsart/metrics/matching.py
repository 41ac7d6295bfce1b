"""Matching predicted movable parts to true ones (DESIGN.md §6.3).

Linear assignment (Hungarian, ``scipy.optimize.linear_sum_assignment``) on the ArtGS cost
``Axis Ang + 10·line distance (revolute true joints) + Part Motion``, with type-consistent pairs
first: a pair whose predicted type differs from the true type costs an extra ``TYPE_PENALTY``,
larger than any sum of real costs, so the optimum uses as many type-consistent pairs as exist and
minimises the cost among those. This is the optimum of ArtGS's brute-force permutation search
without its n! cost, and it also handles different part counts (rectangular matrices):
``min(n_pred, n_true)`` pairs; the rest are unmatched.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from .joints import JointEstimate, joint_errors

TYPE_PENALTY = 1e6


@dataclass
class Match:
    """Result of :func:`match_parts`. ``pairs``: (pred index, true index), sorted by true index."""

    pairs: list[tuple[int, int]]
    unmatched_true: list[int]
    unmatched_pred: list[int]
    cost: np.ndarray = field(repr=False)

    def pred_for_true(self, t: int) -> int | None:
        for p, q in self.pairs:
            if q == t:
                return p
        return None


def pair_cost(pred: JointEstimate, true: JointEstimate) -> float:
    """ArtGS's matching cost of one pair, plus ``TYPE_PENALTY`` when the types differ."""
    e = joint_errors(pred, true)
    c = e["axis_ang"] + (e["axis_pos"] or 0.0) + e["part_motion"]
    return c + (0.0 if pred.type == true.type else TYPE_PENALTY)


def match_parts(pred: list[JointEstimate], true: list[JointEstimate]) -> Match:
    """Optimal assignment of predicted to true joints (either list may be empty or longer)."""
    n_p, n_t = len(pred), len(true)
    cost = np.zeros((n_p, n_t))
    for i, p in enumerate(pred):
        for j, t in enumerate(true):
            cost[i, j] = pair_cost(p, t)
    if n_p == 0 or n_t == 0:
        return Match([], list(range(n_t)), list(range(n_p)), cost)
    rows, cols = linear_sum_assignment(cost)
    pairs = sorted(((int(r), int(c)) for r, c in zip(rows, cols)), key=lambda rc: rc[1])
    mt = {c for _, c in pairs}
    mp = {r for r, _ in pairs}
    return Match(pairs, [j for j in range(n_t) if j not in mt], [i for i in range(n_p) if i not in mp], cost)
