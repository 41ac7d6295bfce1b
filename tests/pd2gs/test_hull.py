"""RGB-only visual-hull initialisation: a ball seen from a ring of cameras, per-state union, fallback."""
from __future__ import annotations

import numpy as np
import torch

from pd2gs.data import Frame
from pd2gs.hull import hull_points, visual_hull
from rsart.camera import look_at

BG = (1.0, 1.0, 1.0)
W, H, F = 96, 72, 80.0


def _ball_frames(centre, radius, state, n=12):
    """Exact silhouettes of a ball (dark on white) from n cameras on a ring around it."""
    K = np.array([[F, 0, W / 2], [0, F, H / 2], [0, 0, 1.0]])
    frames = []
    for i in range(n):
        a = 2 * np.pi * i / n
        eye = np.array([2.0 * np.cos(a), 2.0 * np.sin(a), 0.8])
        w2c = np.linalg.inv(look_at(eye, np.zeros(3)))
        u, v = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
        rays = np.stack([(u - K[0, 2]) / F, (v - K[1, 2]) / F, np.ones_like(u)], -1)
        rays = rays @ np.linalg.inv(w2c)[:3, :3].T
        rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
        oc = eye - np.asarray(centre)
        b = rays @ oc
        hit = b ** 2 - (oc @ oc - radius ** 2) > 0
        rgb = np.ones((H, W, 3), np.float32)
        rgb[hit] = 0.2
        frames.append(Frame(torch.from_numpy(rgb), None, torch.tensor(K, dtype=torch.float32),
                            torch.tensor(w2c, dtype=torch.float32), state, "train"))
    return frames


def test_hull_of_a_ball_hugs_the_ball():
    frames = _ball_frames([0.0, 0.0, 0.0], 0.2, 0)
    pts = visual_hull(frames, BG, [-0.5] * 3, [0.5] * 3, resolution=48)
    r = np.linalg.norm(pts, axis=1)
    assert len(pts) > 100
    assert r.max() < 0.2 * 1.3          # a hull from 12 views is a little larger than the ball
    ball = np.stack(np.meshgrid(*[np.linspace(-0.15, 0.15, 7)] * 3), -1).reshape(-1, 3)
    ball = ball[np.linalg.norm(ball, axis=1) < 0.15]
    step = 1.0 / 48
    d = np.min(np.linalg.norm(ball[:, None] - pts[None], axis=-1), axis=1)
    assert d.max() < step               # every interior point of the ball is covered


def test_union_over_states_keeps_a_part_in_both_positions():
    frames = _ball_frames([-0.2, 0.0, 0.0], 0.1, 0) + _ball_frames([0.2, 0.0, 0.0], 0.1, 1)
    pts = visual_hull(frames, BG, [-0.5] * 3, [0.5] * 3, resolution=48)
    assert (pts[:, 0] < -0.1).any() and (pts[:, 0] > 0.1).any()
    assert not (np.abs(pts[:, 0]) < 0.05).any()  # the gap between the two positions stays empty


def test_no_foreground_means_no_hull():
    frames = _ball_frames([0.0, 0.0, 0.0], 0.2, 0)
    for f in frames:
        f.rgb[:] = 1.0
    assert hull_points(frames, BG, [-0.5] * 3, [0.5] * 3, 1000, 0) is None
    p = hull_points(_ball_frames([0.0, 0.0, 0.0], 0.2, 0), BG, [-0.5] * 3, [0.5] * 3, 1000, 0)
    assert p.shape == (1000, 3) and float(p.norm(dim=1).max()) < 0.3
