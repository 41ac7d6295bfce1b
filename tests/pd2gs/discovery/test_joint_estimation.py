"""Joint parameters from known rigid motions, both joint-type rules, robustness to outliers."""
import math

import numpy as np
import pytest

from pd2gs.kinematics import (estimate_joint, kabsch, paper_ratio, revolute_params,
                                        rotation_axis_angle)
from rsart.kinematics import joint_motion, rotation_matrix
from synthetic import DOOR, DRAWER, STATES, articulated_means


def line_dist(o1, d1, o2, d2):
    n = np.cross(d1, d2)
    if np.linalg.norm(n) < 1e-9:
        return float(np.linalg.norm(np.cross(o2 - o1, d1)))
    return abs(float((o2 - o1) @ n / np.linalg.norm(n)))


def test_kabsch_recovers_a_rigid_motion():
    rng = np.random.default_rng(0)
    P = rng.normal(size=(50, 3))
    R = rotation_matrix(np.array([1.0, 2.0, 3.0]), 0.7)
    t = np.array([0.1, -0.2, 0.3])
    R2, t2 = kabsch(P, P @ R.T + t)
    assert np.allclose(R2, R, atol=1e-10) and np.allclose(t2, t, atol=1e-10)


def test_axis_angle_and_pivot_off_origin():
    a = np.array([1.0, 1.0, 0.5]); a /= np.linalg.norm(a)
    o = np.array([0.4, -0.3, 0.2])
    Ts = [joint_motion("revolute", a, o, v) for v in (0.3, 0.9)]
    u, ang = rotation_axis_angle(Ts[1][:3, :3])
    assert np.allclose(u, a) and math.isclose(ang, 0.9)
    centroid = np.array([1.0, 0.0, 0.0])
    u, piv, vals = revolute_params([T[:3, :3] for T in Ts], [T[:3, 3] for T in Ts], centroid)
    assert line_dist(piv, u, o, a) < 1e-9
    assert np.allclose(vals, [0.3, 0.9])
    # the pivot is the axis point closest to the centroid
    assert abs(float((centroid - piv) @ u)) < 1e-9


@pytest.mark.parametrize("rule", ["paper", "bic"])
def test_exact_door_and_drawer(rule):
    m, lab = articulated_means()
    door = estimate_joint(m[:, lab == 1], STATES, "m0", "m3", rule=rule)
    assert door.type == "revolute"
    assert np.allclose(door.axis, DOOR["axis"], atol=1e-9)
    assert line_dist(door.origin, door.axis, DOOR["origin"], DOOR["axis"]) < 1e-9
    assert np.allclose([door.values[s] for s in STATES], DOOR["values"], atol=1e-9)
    drawer = estimate_joint(m[:, lab == 2], STATES, "m0", "m3", rule=rule)
    assert drawer.type == "prismatic"
    assert np.allclose(drawer.axis, DRAWER["axis"], atol=1e-9)
    assert np.allclose([drawer.values[s] for s in STATES], DRAWER["values"], atol=1e-9)


def test_outliers_do_not_move_the_estimate():
    m, lab = articulated_means(outliers=30)            # 10 % of each part moves randomly by ~5 cm
    door = estimate_joint(m[:, lab == 1], STATES, "m0", "m3", rule="bic")
    assert door.type == "revolute"
    assert math.degrees(math.acos(min(1.0, abs(door.axis @ DOOR["axis"])))) < 0.01
    assert line_dist(door.origin, door.axis, DOOR["origin"], DOOR["axis"]) < 1e-6
    assert abs(door.values["m3"] - 1.2) < 1e-6
    assert door.diagnostics["inlier_frac"] < 0.95      # the outliers were rejected
    drawer = estimate_joint(m[:, lab == 2], STATES, "m0", "m3", rule="bic")
    assert abs(drawer.values["m3"] - 0.15) < 1e-6


def test_noisy_estimates_stay_close():
    m, lab = articulated_means(noise=0.001, seed=3)
    door = estimate_joint(m[:, lab == 1], STATES, "m0", "m3", rule="bic")
    assert door.type == "revolute"
    assert math.degrees(math.acos(min(1.0, abs(door.axis @ DOOR["axis"])))) < 1.0
    assert line_dist(door.origin, door.axis, DOOR["origin"], DOOR["axis"]) < 0.01
    drawer = estimate_joint(m[:, lab == 2], STATES, "m0", "m3", rule="bic")
    assert drawer.type == "prismatic" and abs(drawer.values["m3"] - 0.15) < 0.002


def test_axis_sign_makes_the_end_value_positive():
    m, lab = articulated_means()
    m = m[::-1]                                         # now the door closes from m0 to m3
    door = estimate_joint(m[:, lab == 1], STATES, "m0", "m3")
    assert door.values["m3"] > 0 and np.allclose(door.axis, -DOOR["axis"], atol=1e-9)


def test_paper_rule_is_thickness_limited_and_bic_is_not():
    """The paper's rank rule needs a flat part: a revolute block (as thick as wide) reads 'prismatic'."""
    rng = np.random.default_rng(0)
    block = rng.uniform([0.0, 0.0, 0.0], [0.2, 0.2, 0.2], size=(400, 3))
    a, o = np.array([0.0, 0.0, 1.0]), np.array([-0.05, 0.0, 0.0])
    Qs = np.stack([block @ joint_motion("revolute", a, o, v)[:3, :3].T + joint_motion("revolute", a, o, v)[:3, 3]
                   for v in (0.0, 0.2, 0.4, 0.6)])
    r, _ = paper_ratio(Qs[0], Qs[3])
    assert r > 0.5
    j = estimate_joint(Qs, STATES, "m0", "m3", rule="paper")
    assert j.type == "prismatic" and j.type_paper == "prismatic" and j.type_bic == "revolute"
    j = estimate_joint(Qs, STATES, "m0", "m3", rule="bic")
    assert j.type == "revolute" and line_dist(j.origin, j.axis, o, a) < 1e-9


def test_a_fit_scores_as_rsart_joint_estimate():
    """pd2gs's JointFit hands the metrics rsart's one JointEstimate (delta = value[end] - value[start])."""
    from rsart.metrics.joints import JointEstimate, joint_errors

    m, lab = articulated_means()
    fit = estimate_joint(m[:, lab == 1], STATES, "m0", "m3", rule="bic")
    est = fit.estimate("m0", "m3")
    assert isinstance(est, JointEstimate) and est.type == "revolute"
    assert math.isclose(est.delta, fit.values["m3"] - fit.values["m0"])
    true = JointEstimate.make("revolute", DOOR["axis"], DOOR["origin"], DOOR["values"][-1])
    err = joint_errors(est, true)
    assert err["axis_ang"] < 1e-6 and err["axis_pos"] < 1e-6 and err["part_motion"] < 1e-6
    assert err["type_correct"] == 1.0
