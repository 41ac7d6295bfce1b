"""Hand-computed cases for Axis Ang, Axis Pos and Part Motion (and the peers' reference values)."""
import math

import numpy as np
import pytest

from rsart.kinematics import rotation_matrix
from rsart.metrics.joints import (JointEstimate, axis_angle_deg, axis_position, joint_errors, line_distance,
                                  part_motion, rotation_geodesic_deg)

pytestmark = pytest.mark.core  # runs on the core install alone (.ci/core)


def tilted(axis, deg, about):
    return rotation_matrix(np.asarray(about, float), math.radians(deg)) @ np.asarray(axis, float)


def quat_geodesic_deg(a1, a2, theta):
    """Independent closed form: angle between Rot(a1, θ) and Rot(a2, θ) via unit quaternions."""
    c = math.cos(theta / 2) ** 2 + math.sin(theta / 2) ** 2 * float(np.dot(a1, a2))
    return math.degrees(2 * math.acos(min(1.0, abs(c))))


def test_axis_angle_is_sign_invariant():
    a = np.array([0.0, 0.0, 1.0])
    assert axis_angle_deg(a, -a) == 0.0
    assert axis_angle_deg(a, a) == 0.0
    assert axis_angle_deg([1, 0, 0], [0, 1, 0]) == pytest.approx(90.0)
    assert axis_angle_deg([1, 0, 0], [-1, 1, 0]) == pytest.approx(45.0)  # 135° between vectors -> 45° between lines
    assert axis_angle_deg([2, 0, 0], [0, 0, 5]) == pytest.approx(90.0)   # lengths do not matter


def test_axis_angle_never_nan_for_near_identical_axes():
    rng = np.random.default_rng(0)
    for _ in range(2000):
        a = rng.normal(size=3)
        a /= np.linalg.norm(a)
        v = axis_angle_deg(a, a * 1.0000000001)
        assert v == v and 0.0 <= v < 1e-5


def test_parallel_lines_use_point_to_line_distance():
    assert line_distance([0, 0, 0], [0, 0, 1], [0.3, 0, 5], [0, 0, 1]) == pytest.approx(0.3)
    assert line_distance([0, 0, 0], [0, 0, 1], [0.3, 0.4, 0], [0, 0, -1]) == pytest.approx(0.5)
    assert axis_position([0, 0, 0], [0, 0, 1], [0.3, 0.4, 0], [0, 0, -1]) == pytest.approx(5.0)


def test_skew_and_intersecting_lines():
    # x axis through the origin, y direction through (0, 0, 0.05): 0.05 apart
    assert line_distance([0, 0, 0], [1, 0, 0], [7, 3, 0.05], [0, 1, 0]) == pytest.approx(0.05)
    # intersecting lines: 0
    assert line_distance([0, 0, 0], [1, 0, 0], [2, -1, 0], [0, 1, 0]) == pytest.approx(0.0, abs=1e-15)


def test_revolute_part_with_tilted_axis_reference_values():
    """Peers' reference (notes): axis tilted 5°, 60° opening: 5 / 0 / 4.9988."""
    a = np.array([0.0, 0.0, 1.0])
    a5 = tilted(a, 5.0, [1, 0, 0])
    o = np.array([0.2, 0.1, 0.0])
    t = JointEstimate.make("revolute", a, o, math.radians(60))
    p = JointEstimate.make("revolute", a5, o, math.radians(60))
    e = joint_errors(p, t)
    assert e["axis_ang"] == pytest.approx(5.0, abs=1e-9)
    assert e["axis_pos"] == pytest.approx(0.0, abs=1e-12)
    assert e["part_motion"] == pytest.approx(quat_geodesic_deg(a5, a, math.radians(60)), abs=1e-7)
    assert round(e["part_motion"], 4) == 4.9988
    assert e["type_correct"] == 1.0


def test_skew_axes_reference_values():
    """Peers' reference: skew axes 10° apart and 0.05 apart, 60° opening: 10 / 0.5 / 9.9905."""
    t = JointEstimate.make("revolute", [0, 0, 1], [0, 0, 0], math.radians(60))
    p = JointEstimate.make("revolute", tilted([0, 0, 1], 10.0, [0, 1, 0]), [0, 0.05, 0], math.radians(60))
    e = joint_errors(p, t)
    assert e["axis_ang"] == pytest.approx(10.0, abs=1e-9)
    assert e["axis_pos"] == pytest.approx(0.5, abs=1e-9)
    assert round(e["part_motion"], 4) == 9.9905


def test_revolute_angle_error_only():
    t = JointEstimate.make("revolute", [0, 1, 0], [0, 0, 0], math.radians(70))
    p = JointEstimate.make("revolute", [0, -1, 0], [0, 0, 0], -math.radians(80))  # flipped axis, negated angle
    e = joint_errors(p, t)
    assert e["axis_ang"] == 0.0
    assert e["part_motion"] == pytest.approx(10.0, abs=1e-9)


def test_prismatic_motion():
    t = JointEstimate.make("prismatic", [1, 0, 0], None, 0.30)
    e = joint_errors(JointEstimate.make("prismatic", [1, 0, 0], [5, 5, 5], 0.25), t)
    assert e["part_motion"] == pytest.approx(0.05, abs=1e-12)
    assert e["axis_pos"] is None  # Axis Pos is revolute-only
    assert e["axis_ang"] == 0.0
    # reversed direction with the same travel: 0° axis error but twice the travel
    e = joint_errors(JointEstimate.make("prismatic", [-1, 0, 0], None, 0.30), t)
    assert e["axis_ang"] == 0.0 and e["part_motion"] == pytest.approx(0.6)
    # tilted by 90°: |0.3 x - 0.3 y|
    assert part_motion("prismatic", [0, 1, 0], 0.3, [1, 0, 0], 0.3) == pytest.approx(0.3 * math.sqrt(2))


def test_type_mismatch_is_read_with_the_true_type():
    t = JointEstimate.make("revolute", [0, 0, 1], [0, 0, 0], math.radians(90))
    p = JointEstimate.make("prismatic", [0, 0, 1], [0, 0, 0], 0.2)  # 0.2 read as radians
    e = joint_errors(p, t)
    assert e["type_correct"] == 0.0
    assert e["part_motion"] == pytest.approx(90.0 - math.degrees(0.2), abs=1e-9)
    assert e["axis_pos"] == pytest.approx(0.0)


def test_part_predicted_not_to_move():
    t = JointEstimate.make("revolute", [0, 0, 1], [0, 0, 0], math.radians(45))
    e = joint_errors(JointEstimate.make("revolute", [0, 0, 1], [0, 0, 0], 0.0), t)
    assert e["part_motion"] == pytest.approx(45.0)


def test_geodesic_and_bad_axis():
    assert rotation_geodesic_deg(np.eye(3), rotation_matrix(np.array([1.0, 2, 3]), 0.5)) == pytest.approx(math.degrees(0.5))
    with pytest.raises(ValueError):
        JointEstimate.make("revolute", [0, 0, 0], [0, 0, 0], 0.1)
