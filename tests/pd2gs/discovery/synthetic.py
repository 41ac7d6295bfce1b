"""Synthetic articulated Gaussian centres for the discovery tests (no training, exact motions)."""
from __future__ import annotations

import numpy as np

from rsart.kinematics import joint_motion

STATES = ["m0", "m1", "m2", "m3"]
DOOR = {"type": "revolute", "axis": np.array([0.0, 0.0, 1.0]), "origin": np.array([0.3, -0.2, 0.0]),
        "values": [0.0, 0.4, 0.8, 1.2]}
DRAWER = {"type": "prismatic", "axis": np.array([1.0, 0.0, 0.0]) , "origin": np.zeros(3),
          "values": [0.0, 0.05, 0.1, 0.15]}


def box_points(rng: np.random.Generator, lo, hi, n: int) -> np.ndarray:
    return rng.uniform(lo, hi, size=(n, 3))


def articulated_means(n_base=600, n_door=300, n_drawer=300, seed=0, outliers=0, noise=0.0):
    """(K=4, N, 3) centres of a base + a door (revolute about an off-origin z axis) + a drawer (prismatic x)
    and (N,) true labels 0/1/2. ``outliers`` extra Gaussians per part move randomly."""
    rng = np.random.default_rng(seed)
    base = box_points(rng, [-0.3, -0.2, 0.0], [0.3, 0.2, 0.5], n_base)
    door = box_points(rng, [0.3, -0.2, 0.25], [0.31, 0.2, 0.5], n_door)   # flat lid on the x+ face, hinge at y=-0.2
    drawer = box_points(rng, [0.0, -0.18, 0.02], [0.3, 0.18, 0.2], n_drawer)
    pts = [base, door, drawer]
    labels = np.concatenate([np.full(len(p), i) for i, p in enumerate(pts)])
    out = []
    for k in range(4):
        Td = joint_motion("revolute", DOOR["axis"], DOOR["origin"], DOOR["values"][k])
        Tp = joint_motion("prismatic", DRAWER["axis"], DRAWER["origin"], DRAWER["values"][k])
        out.append(np.concatenate([base, door @ Td[:3, :3].T + Td[:3, 3], drawer + Tp[:3, 3]]))
    means = np.stack(out)
    if noise:
        means = means + rng.normal(scale=noise, size=means.shape)
    if outliers:
        for lab in (1, 2):
            idx = rng.choice(np.flatnonzero(labels == lab), outliers, replace=False)
            means[1:, idx] += rng.normal(scale=0.05, size=(3, outliers, 3))
    return means, labels
