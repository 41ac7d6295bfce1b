"""Static/dynamic split, trajectory clustering and rigid-motion clustering on exact synthetic motions."""
import numpy as np
from sklearn.metrics import adjusted_rand_score

from pd2gs.discovery.motion import (cluster_rigid_motions, cluster_trajectories, coarse_labels, dynamic_mask,
                                    max_displacement, trajectory_descriptors)
from synthetic import articulated_means


def test_max_displacement_is_over_all_state_pairs():
    m = np.zeros((3, 1, 3))
    m[1, 0] = [1, 0, 0]
    m[2, 0] = [-1, 0, 0]          # states 1 and 2 are 2 apart, each 1 from state 0
    assert max_displacement(m)[0] == 2.0


def test_dynamic_mask_separates_base_from_moving_parts():
    m, lab = articulated_means()
    dyn = dynamic_mask(m, 0.15)
    assert not dyn[lab == 0].any()
    assert dyn[lab == 2].all()                     # the whole drawer slides 15 cm
    # door points near the hinge barely move: those (and only those) stay static
    d = max_displacement(m)
    assert np.array_equal(dyn[lab == 1], d[lab == 1] / d.max() >= 0.15)
    assert dyn[lab == 1].mean() > 0.7


def test_descriptor_shape_and_norm():
    m, _ = articulated_means()
    f = trajectory_descriptors(m)
    assert f.shape == (m.shape[1], 4 * 3)
    moving = np.linalg.norm(m[-1] - m[0], axis=1) > 0
    assert np.allclose(np.linalg.norm(f[moving], axis=1), 1.0)


def test_clustering_recovers_the_two_rigid_parts():
    m, lab = articulated_means()
    labels = coarse_labels(m, 2, 0.15)
    dyn = labels > 0
    assert adjusted_rand_score(lab[dyn], labels[dyn]) > 0.99
    assert set(np.unique(labels)) == {0, 1, 2}


def test_clustering_with_noise_and_two_states():
    m, lab = articulated_means(noise=0.002)
    m2 = m[[0, 3]]
    labels = coarse_labels(m2, 2, 0.15)
    dyn = labels > 0
    assert adjusted_rand_score(lab[dyn], labels[dyn]) > 0.95


def test_small_clusters_are_merged():
    m, lab = articulated_means()
    dyn = dynamic_mask(m, 0.15)
    md = m[:, dyn].copy()
    md[:, :3] += np.random.default_rng(1).normal(scale=0.3, size=(4, 3, 3))   # 3 wild points (< 2 %)
    labels = cluster_trajectories(md, 3, min_frac=0.02)
    assert len(np.unique(labels)) == 2
    assert set(np.unique(labels)) == {1, 2}


def test_split_disconnected_separates_parts_that_move_together():
    from pd2gs.discovery.motion import split_disconnected
    rng = np.random.default_rng(0)
    a = rng.uniform([0, 0, 0], [0.3, 0.2, 0.01], (300, 3))          # two drawer fronts 5 cm apart,
    b = rng.uniform([0, 0.25, 0], [0.3, 0.45, 0.01], (300, 3))      # same cluster (same motion)
    speck = np.array([[0.1, 0.21, 0.0]])                             # one stray point between them
    base = rng.uniform([-0.5, -0.5, -0.5], [0.5, 0.5, -0.4], (200, 3))
    pts = np.concatenate([a, b, speck, base])
    labels = np.concatenate([np.ones(601, int), np.zeros(200, int)])
    out = split_disconnected(pts, labels, min_size=12)
    assert set(out[:300]) == {1} or set(out[:300]) == {2}
    assert set(out[300:600]) == ({1, 2} - set(out[:300]))
    assert out[600] in (1, 2) and (out[200 + 400:] == 0)[1:].all()
    # one connected cluster stays one part
    assert np.array_equal(split_disconnected(pts[:300], np.ones(300, int), 12), np.ones(300, int))


def _door_with_handle(seed: int = 0):
    """(K=4, N, 3) centres of a door leaf (hinge: z axis at x = y = 0, up to 80 deg) with a handle chained
    to it (turning 40 deg about the leaf's normal), and (N,) labels 1 leaf / 2 handle."""
    from rsart.kinematics import joint_motion

    rng = np.random.default_rng(seed)
    leaf = rng.uniform([0.0, -0.01, 0.0], [0.8, 0.01, 2.0], (1500, 3))
    handle = rng.uniform([0.6, -0.06, 0.95], [0.75, -0.02, 1.0], (150, 3))
    out = []
    for s in (0.0, 1 / 3, 2 / 3, 1.0):
        T_leaf = joint_motion("revolute", np.array([0.0, 0.0, 1.0]), np.zeros(3), 1.4 * s)
        T_handle = T_leaf @ joint_motion("revolute", np.array([0.0, 1.0, 0.0]), np.array([0.7, 0.0, 0.975]), 0.7 * s)
        out.append(np.concatenate([leaf @ T_leaf[:3, :3].T + T_leaf[:3, 3],
                                   handle @ T_handle[:3, :3].T + T_handle[:3, 3]]))
    return np.stack(out), np.r_[np.ones(len(leaf), int), np.full(len(handle), 2)]


def test_rigid_clustering_keeps_a_rotating_leaf_whole_and_finds_its_chained_handle():
    """The paper's descriptor carries displacement length, so k-means on it splits a leaf by distance from
    its hinge; clustering by rigid motion keeps it whole and separates the small handle hanging from it."""
    m, lab = _door_with_handle()
    rigid = cluster_rigid_motions(m, 2)
    assert adjusted_rand_score(lab, rigid) > 0.95
    assert adjusted_rand_score(lab, cluster_trajectories(m, 2)) < 0.5  # why "rigid" exists


def test_rigid_clustering_recovers_the_two_rigid_parts_with_outliers():
    m, lab = articulated_means(outliers=20, noise=0.002)
    labels = coarse_labels(m, 2, 0.15, method="rigid")
    dyn = labels > 0
    assert adjusted_rand_score(lab[dyn], labels[dyn]) > 0.95


def test_rigid_clustering_merges_a_too_small_cluster():
    m, lab = _door_with_handle()
    assert set(cluster_rigid_motions(m, 2, min_frac=0.2)) == {1}  # the handle (9 %) is under 20 %
