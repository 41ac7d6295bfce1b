"""The cpu backend's Numba projection matches the PyTorch projection (values and gradients)."""
from __future__ import annotations

import math

import pytest
import torch

from pd2gs.render.projection import project_gaussians
from pd2gs.render.projection_cpu import project_gaussians_cpu


def _scene(n: int, dtype: torch.dtype, seed: int):
    """n Gaussians in [-0.5, 0.5]^3: means (n, 3), unnormalised quats (n, 4), scales (n, 3)."""
    g = torch.Generator().manual_seed(seed)
    means = torch.rand(n, 3, generator=g) - 0.5
    quats = torch.randn(n, 4, generator=g)
    scales = 0.7 * n ** (-1 / 3) * torch.exp(0.3 * torch.randn(n, 3, generator=g))
    return [t.to(dtype).requires_grad_() for t in (means, quats, scales)]


def _camera(width: int, height: int, dtype: torch.dtype):
    """Off-centre, rotated OpenCV camera 1.2 m from the cube: some Gaussians leave the view,
    some hit the 1.3x FOV clamp of the Jacobian, some lie behind the near plane."""
    f = 0.5 * width / math.tan(math.radians(20))
    K = torch.tensor([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]], dtype=dtype)
    w2c = torch.eye(4, dtype=dtype)
    w2c[:3, :3] = torch.tensor([[0.96, 0.0, -0.28], [0.0, 1.0, 0.0], [0.28, 0.0, 0.96]], dtype=dtype)
    w2c[0, 3], w2c[2, 3] = 0.4, 0.6
    return K, w2c


def _project_and_grads(fn, params, K, w2c, width, height):
    means, quats, scales = params
    pr = fn(means, quats, scales, K, w2c, width, height)
    g = torch.Generator().manual_seed(3)
    dt = means.dtype
    loss = sum((getattr(pr, name) * torch.randn(getattr(pr, name).shape, generator=g).to(dt)).sum()
               for name in ("means2d", "conics", "depths"))
    return pr, torch.autograd.grad(loss, params)


@pytest.mark.parametrize("dtype,tol", [(torch.float64, 1e-10), (torch.float32, 1e-5)])
def test_numba_projection_matches_torch(dtype, tol):
    width, height = 64, 48
    params = _scene(2000, dtype, 11)
    K, w2c = _camera(width, height, dtype)
    ref, gref = _project_and_grads(project_gaussians, params, K, w2c, width, height)
    fast, gfast = _project_and_grads(project_gaussians_cpu, params, K, w2c, width, height)
    visible = ref.radii > 0
    assert 0 < int(visible.sum()) < 2000  # both culled and visible Gaussians are exercised
    assert torch.equal(fast.radii > 0, visible)
    assert (fast.radii != ref.radii).float().mean() < 1e-3  # ceil() may flip in float32
    for name in ("means2d", "conics", "depths"):
        a, b = getattr(fast, name).detach()[visible], getattr(ref, name).detach()[visible]
        assert float((a - b).abs().max() / b.abs().max()) < tol, name
    for name, a, b in zip(("means", "quats", "scales"), gfast, gref):
        assert b.abs().max() > 0, name
        assert float((a - b).abs().max() / b.abs().max()) < tol, name
