"""Hungarian matching of predicted to true movable parts."""
import math

import numpy as np
import pytest

from rsart.metrics.joints import JointEstimate
from rsart.metrics.matching import TYPE_PENALTY, match_parts

pytestmark = pytest.mark.core  # runs on the core install alone (.ci/core)


def joints():
    return [
        JointEstimate.make("revolute", [0, 0, 1], [0.3, 0, 0], math.radians(90)),
        JointEstimate.make("prismatic", [1, 0, 0], None, 0.3),
        JointEstimate.make("revolute", [1, 0, 0], [0, 0, 0.5], math.radians(45)),
        JointEstimate.make("prismatic", [0, 1, 0], None, 0.1),
    ]


def test_recovers_a_shuffled_order():
    true = joints()
    perm = [2, 0, 3, 1]
    pred = [true[i] for i in perm]
    m = match_parts(pred, true)
    assert m.unmatched_true == [] and m.unmatched_pred == []
    for p, t in m.pairs:
        assert perm[p] == t


def test_more_predicted_parts():
    true = joints()[:2]
    extra = JointEstimate.make("revolute", [0, 1, 0], [9, 9, 9], 1.0)
    pred = [extra, true[1], true[0]]
    m = match_parts(pred, true)
    assert m.pairs == [(2, 0), (1, 1)]
    assert m.unmatched_pred == [0] and m.unmatched_true == []


def test_fewer_predicted_parts():
    true = joints()
    m = match_parts([true[2]], true)
    assert m.pairs == [(0, 2)]
    assert m.unmatched_true == [0, 1, 3]
    assert m.pred_for_true(2) == 0 and m.pred_for_true(0) is None


def test_type_consistent_pairs_come_first():
    true = [JointEstimate.make("revolute", [0, 0, 1], [0, 0, 0], 1.0),
            JointEstimate.make("prismatic", [1, 0, 0], None, 0.3)]
    # the prismatic prediction is geometrically closer to the revolute truth (same axis), but types win
    pred = [JointEstimate.make("prismatic", [0, 0, 1], [0, 0, 0], 0.3),
            JointEstimate.make("revolute", [1, 0, 0], [0, 0, 0], 1.0)]
    m = match_parts(pred, true)
    assert sorted(m.pairs) == [(0, 1), (1, 0)]
    assert np.all(m.cost[0, 0] >= TYPE_PENALTY)


def test_empty_inputs():
    m = match_parts([], joints())
    assert m.pairs == [] and m.unmatched_true == [0, 1, 2, 3]
    m = match_parts(joints()[:1], [])
    assert m.unmatched_pred == [0]
