"""The default part counter: local rigid motions, silhouette model selection over k."""
import numpy as np
import pytest

from pd2gs.discovery.counter import count_by_trajectories, local_rigid_motions
from rsart.kinematics import joint_motion


def moving_parts(n_parts, noise, seed=0, n=300):
    """(4, n_parts*n, 3) centres of n_parts boxes, each under its own joint over 4 states, with non-rigid noise."""
    rng = np.random.default_rng(seed)
    joints = [("revolute", [0, 0, 1], [0.3, 0, 0], 1.5), ("prismatic", [0, -1, 0], [0, 0, 0], 0.3),
              ("revolute", [1, 0, 0], [0, 0, 0.5], -1.0), ("prismatic", [1, 0, 0], [0, 0, 0], 0.25)][:n_parts]
    out = []
    for p, (typ, ax, o, amount) in enumerate(joints):
        pts = rng.uniform(-0.1, 0.1, (n, 3)) + np.array([0.1 * p, 0.2 * p, 0.3])
        states = []
        for t in np.linspace(0, 1, 4):
            T = joint_motion(typ, np.array(ax, float), np.array(o, float), t * amount)
            states.append(pts @ T[:3, :3].T + T[:3, 3] + rng.normal(0, noise, pts.shape))
        out.append(np.stack(states))
    return np.concatenate(out, axis=1)


@pytest.mark.parametrize("n_parts", [1, 2, 3])
def test_counts_parts_under_non_rigid_noise(n_parts):
    means = moving_parts(n_parts, noise=0.01)
    n, diag = count_by_trajectories(local_rigid_motions(means), max_parts=6)
    assert n == n_parts, diag


def test_too_few_points_is_one_or_zero():
    assert count_by_trajectories(np.zeros((0, 6)))[0] == 0
    assert count_by_trajectories(np.ones((5, 6)))[0] == 1
