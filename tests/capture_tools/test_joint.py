"""Pieces of the joint SfM mode: the cross-state match filter and the one-transform twin registration."""
from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from capture_tools.joint import cross_state_filter, register_twin_joint
from capture_tools.pose_eval import rotation_angle_deg
from capture_tools.register import outer_surface_samples


def test_cross_state_filter_keeps_same_state_pairs_and_static_cross_matches():
    H, W = 20, 30
    left = np.zeros((H, W), bool)
    left[:, :15] = True  # static w.r.t. the other state on the left half only
    static = {"a1.png": {"b": left}, "a2.png": {"b": left}, "b1.png": {"a": np.ones((H, W), bool)}}
    groups = {"a1.png": "a", "a2.png": "a", "b1.png": "b"}
    f = cross_state_filter(groups, static)
    xy = np.array([[2.0, 5.0], [20.0, 5.0], [14.4, 3.0], [14.6, 3.0]])  # x = 14.6 rounds to column 15 (moved)
    m = np.array([[0, 0], [1, 1], [2, 2], [3, 3]])
    assert f("a1.png", "a2.png", xy, xy, m) is None  # within a state: every verified match stays
    keep = f("a1.png", "b1.png", xy, xy, m)
    assert keep.tolist() == [True, False, True, False]
    keep = f("b1.png", "a1.png", xy, xy, m)  # the mask of the image from the other state is used on each side
    assert keep.tolist() == [True, False, True, False]


def test_register_twin_joint_recovers_one_transform_from_two_states():
    rng = np.random.default_rng(0)
    base = trimesh.creation.box(extents=[0.3, 0.24, 0.16])
    base.apply_translation([0, 0, 0.08])
    lid_closed = trimesh.creation.box(extents=[0.3, 0.24, 0.02])
    lid_closed.apply_translation([0, 0, 0.17])
    lid_open = lid_closed.copy()
    lid_open.apply_transform(trimesh.transformations.rotation_matrix(1.2, [0, -1, 0], [-0.15, 0, 0.16]))
    meshes = [trimesh.util.concatenate([base, lid_closed]), trimesh.util.concatenate([base, lid_open])]
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", [10, -20, 35], degrees=True).as_matrix()
    T[:3, 3] = [0.1, -0.2, 0.6]
    clouds = []
    for m in meshes:
        p = outer_surface_samples(m, 4000, seed=1)[0]  # what a camera can see (no lid underside on the body)
        p = p + rng.normal(0, 0.001, p.shape)
        clouds.append(p @ T[:3, :3].T + T[:3, 3])
    T0 = T.copy()
    T0[:3, :3] = Rotation.from_rotvec(np.radians([1.5, -1.0, 1.0])).as_matrix() @ T[:3, :3]
    T0[:3, 3] += [0.006, -0.004, 0.005]
    est = register_twin_joint(meshes, clouds, T0, n_samples=20000)
    assert rotation_angle_deg(est[None, :3, :3], T[None, :3, :3])[0] < 0.1
    assert np.linalg.norm(est[:3, 3] - T[:3, 3]) < 0.001
