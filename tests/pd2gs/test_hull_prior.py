"""Per-state visual hulls and the hull prior (distance to hull k, coverage of hull k) on exact ball silhouettes."""
from __future__ import annotations

import numpy as np
import torch

from pd2gs.hull import HullPrior, sample_voxels, state_hulls
from tests.pd2gs.test_hull import BG, _ball_frames

LO, HI = [-0.5] * 3, [0.5] * 3


def _two_state_hulls():
    """State 0: a ball of radius 0.1 at x = -0.25; state 1: the same ball at x = +0.25."""
    frames = _ball_frames([-0.25, 0.0, 0.0], 0.1, 0) + _ball_frames([0.25, 0.0, 0.0], 0.1, 1)
    return state_hulls(frames, BG, LO, HI, resolution=40)


def test_each_state_gets_its_own_hull():
    hg = _two_state_hulls()
    assert hg.occ.shape[0] == 2
    c0, c1 = hg.centres(hg.occ[0]), hg.centres(hg.occ[1])
    assert len(c0) > 50 and len(c1) > 50
    assert (c0[:, 0] < 0).all() and (c1[:, 0] > 0).all()
    assert abs(c0[:, 0].mean() + 0.25) < 0.03 and abs(c1[:, 0].mean() - 0.25) < 0.03
    pts = sample_voxels(hg, hg.occ[1], 500, seed=0)
    assert pts.shape == (500, 3) and (pts[:, 0] > 0.1).all()


def test_outside_distance_is_zero_inside_and_grows_with_distance():
    hg = _two_state_hulls()
    prior = HullPrior(hg, extent=1.0)
    inside = torch.tensor([[0.25, 0.0, 0.0]])
    assert float(prior.outside(inside, 1)) < 1e-6
    assert float(prior.outside(inside, 0)) > 0.3  # the state-0 hull is 0.5 away minus its radius
    near, far = torch.tensor([[0.25, 0.0, 0.25]]), torch.tensor([[0.25, 0.0, 0.4]])
    d_near, d_far = float(prior.outside(near, 1)), float(prior.outside(far, 1))
    assert 0.1 < d_near < 0.2 and d_far > d_near + 0.1
    beyond = torch.tensor([[0.25, 0.0, 0.9]])  # outside the grid box: distance keeps growing
    assert float(prior.outside(beyond, 1)) > d_far + 0.4
    assert abs(float(HullPrior(hg, extent=2.0).outside(far, 1)) - d_far / 2) < 1e-6


def test_outside_gradient_moves_points_into_the_hull():
    hg = _two_state_hulls()
    prior = HullPrior(hg, extent=1.0)
    x = torch.tensor([[-0.25, 0.0, 0.0], [0.0, 0.1, 0.05]], requires_grad=True)
    opt = torch.optim.Adam([x], lr=0.01)
    for _ in range(150):
        opt.zero_grad()
        prior.outside(x, 1).backward()
        opt.step()
    assert float(prior.outside(x.detach(), 1)) < 0.01


def test_coverage_is_small_only_when_opaque_centres_fill_the_hull():
    hg = _two_state_hulls()
    prior = HullPrior(hg, extent=1.0)
    gen = torch.Generator().manual_seed(0)
    filled = sample_voxels(hg, hg.occ[1], 2000, seed=1)
    opaque = torch.ones(2000)
    assert float(prior.coverage(filled, opaque, 1, gen)) < 0.02
    clump = torch.full((2000, 3), 0.25)
    clump[:, 1:] = 0.0
    assert float(prior.coverage(clump, opaque, 1, gen)) > 0.04  # one point cannot cover a ball
    # transparent Gaussians do not count
    assert float(prior.coverage(filled, torch.zeros(2000), 1, gen)) == 0.0
    mixed = torch.cat([clump, filled])
    weights = torch.cat([torch.ones(2000), torch.zeros(2000)])
    assert float(prior.coverage(mixed, weights, 1, gen)) > 0.04


def test_first_state_start_takes_a_share_of_the_union_hull():
    from pd2gs.train import TrainConfig, build_field

    frames = _ball_frames([-0.25, 0.0, 0.0], 0.1, 0) + _ball_frames([0.25, 0.0, 0.0], 0.1, 1)

    def share_on_the_right(init, frac):
        cfg = TrainConfig(states=["a", "b"], init=init, init_union_frac=frac, init_points=400,
                          background=BG, hull_resolution=32)
        x = build_field(cfg, frames).gaussians.means[:, 0]
        return float((x > 0).float().mean())
    assert share_on_the_right("hull0", 0.0) == 0.0          # only the first state's ball
    assert 0.05 < share_on_the_right("hull0", 0.25) < 0.2   # a quarter of the union: about half of it right
    assert 0.3 < share_on_the_right("hull", 0.0) < 0.7      # the union: both balls
