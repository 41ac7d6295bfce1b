"""The local isometry prior: zero for rigid motions, positive for stretches, robust at boundaries."""
from __future__ import annotations

import torch

from pd2gs.rigidity import isometry_loss, knn_graph


def _points(n=300, seed=0):
    return torch.rand(n, 3, generator=torch.Generator().manual_seed(seed))


def test_rigid_motion_costs_nothing():
    x = _points()
    g = knn_graph(x, 8)
    a = torch.tensor(0.7)
    R = torch.tensor([[torch.cos(a), -torch.sin(a), 0.0], [torch.sin(a), torch.cos(a), 0.0], [0.0, 0.0, 1.0]])
    moved = x @ R.T + torch.tensor([0.3, -1.0, 2.0])
    assert float(isometry_loss(moved, g)) < 1e-5


def test_stretch_costs_in_proportion_and_has_a_gradient():
    x = _points()
    g = knn_graph(x, 8)
    small = isometry_loss(x * torch.tensor([1.1, 1.0, 1.0]), g)
    big = isometry_loss(x * torch.tensor([1.5, 1.0, 1.0]), g)
    assert 0 < float(small) < float(big)
    y = (x * 1.2).requires_grad_(True)
    isometry_loss(y, g).backward()
    assert y.grad is not None and float(y.grad.abs().sum()) > 0


def test_graph_shapes_and_scale():
    x = _points(50)
    g = knn_graph(x, 4)
    assert g.idx.shape == (50, 4) and g.rest.shape == (50, 4) and g.n == 50
    assert (g.idx != torch.arange(50)[:, None]).all()  # no self pairs
    assert abs(g.scale - float(g.rest.mean())) < 1e-6
