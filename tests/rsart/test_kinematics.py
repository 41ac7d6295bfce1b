"""Forward kinematics against hand-computed poses."""
import math

import numpy as np
import pytest

from rsart.errors import RsartError
from rsart.format import Joint
from rsart.kinematics import Twin, TwinPart, joint_motion, rotation_matrix
from tests.conftest import box, make_cabinet, make_lamp

pytestmark = pytest.mark.core  # runs on the core install alone (.ci/core)


def apply(T, p):
    return T[:3, :3] @ np.asarray(p, float) + T[:3, 3]


def test_rotation_matrix_quarter_turn_about_z():
    R = rotation_matrix(np.array([0, 0, 1.0]), math.pi / 2)
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-15)


def test_revolute_about_off_origin_axis_hand_computed():
    # axis z through (1, 0, 0); the point (2, 0, 0) turned 90 degrees lands at (1, 1, 0)
    T = joint_motion("revolute", np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), math.pi / 2)
    np.testing.assert_allclose(apply(T, [2, 0, 0]), [1, 1, 0], atol=1e-12)
    # points on the axis do not move
    np.testing.assert_allclose(apply(T, [1, 0, 5]), [1, 0, 5], atol=1e-12)


def test_prismatic_moves_along_axis():
    T = joint_motion("prismatic", np.array([0, 1.0, 0]), np.array([9.0, 9, 9]), 0.3)
    np.testing.assert_allclose(apply(T, [1, 2, 3]), [1, 2.3, 3], atol=1e-15)


def test_cabinet_lid_and_drawer_poses():
    t = make_cabinet()
    T = t.pose({"lid_hinge": math.pi / 2, "drawer_slide": 0.2})
    # lid front edge (0.2, 0, 0.302) rotates about -y through (-0.2, 0, 0.302) by +90 deg:
    # r = (0.4, 0, 0) -> R_-y(90) r = R_y(-90) r = (0, 0, 0.4): the lid stands up
    np.testing.assert_allclose(apply(T[1], [0.2, 0, 0.302]), [-0.2, 0, 0.702], atol=1e-12)
    np.testing.assert_allclose(apply(T[2], [0, 0, 0]), [0.2, 0, 0], atol=1e-15)
    np.testing.assert_allclose(T[0], np.eye(4))


def test_two_joint_chain_composes():
    t = make_lamp()
    # shoulder +90 deg about y at (0,0,0.1): the elbow point (0,0,0.4) -> (0.3, 0, 0.1)
    T = t.pose({"shoulder": math.pi / 2, "elbow": 0.0})
    np.testing.assert_allclose(apply(T[2], [0, 0, 0.4]), [0.3, 0, 0.1], atol=1e-12)
    # add elbow +90 deg: the arm tip (0.25, 0, 0.4) is 0.25 from the elbow along +x at rest;
    # elbow rotation then shoulder rotation: R_y(180) (0.25,0,0) = (-0.25, 0, 0) from the elbow
    T = t.pose({"shoulder": math.pi / 2, "elbow": math.pi / 2})
    np.testing.assert_allclose(apply(T[2], [0.25, 0, 0.4]), [0.3 - 0.25, 0, 0.1], atol=1e-12)
    # the posed elbow axis moved with the shoulder
    o, a = t.posed_axes({"shoulder": math.pi / 2})["elbow"]
    np.testing.assert_allclose(o, [0.3, 0, 0.1], atol=1e-12)
    np.testing.assert_allclose(a, [0, 1, 0], atol=1e-12)


def test_posed_meshes_move_only_the_chain():
    t = make_cabinet()
    rest = t.posed_meshes({})
    moved = t.posed_meshes({"drawer_slide": 0.1})
    np.testing.assert_allclose(rest[0].vertices, moved[0].vertices)
    np.testing.assert_allclose(rest[1].vertices, moved[1].vertices)
    np.testing.assert_allclose(moved[2].vertices - rest[2].vertices, np.tile([0.1, 0, 0], (len(rest[2].vertices), 1)),
                               atol=1e-15)


def test_unknown_joint_name_is_rejected():
    with pytest.raises(KeyError, match="nope"):
        make_cabinet().pose({"nope": 1.0})


def test_structure_errors():
    b = TwinPart(0, "base", box([1, 1, 1], [0, 0, 0]))
    p = TwinPart(1, "p", box([1, 1, 1], [0, 0, 0]))
    q = TwinPart(2, "q", box([1, 1, 1], [0, 0, 0]))
    J = lambda n, par, ch: Joint(n, "revolute", par, ch, np.array([0, 0, 1.0]), np.zeros(3), None)  # noqa: E731
    with pytest.raises(RsartError, match="no joint"):
        Twin("t", [b, p], [])
    with pytest.raises(RsartError, match="cycle"):
        Twin("t", [b, p, q], [J("a", 2, 1), J("b", 1, 2)])
    with pytest.raises(RsartError, match="child of two joints"):
        Twin("t", [b, p], [J("a", 0, 1), J("b", 0, 1)])
