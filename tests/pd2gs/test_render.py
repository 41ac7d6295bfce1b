"""Rasterizer correctness: cpu vs reference, reference vs finite differences, 3DGS rules."""
from __future__ import annotations

import math

import pytest
import torch

from pd2gs.render import BackendUnavailable, rasterize
from pd2gs.render.gsplat_backend import gsplat_status


def random_scene(n: int, dtype: torch.dtype, seed: int, opacity=(0.05, 0.95)):
    """n Gaussians in [-0.5, 0.5]^3 with 3DGS-init-like sizes; returns leaf tensors."""
    g = torch.Generator().manual_seed(seed)
    means = torch.rand(n, 3, generator=g) - 0.5
    quats = torch.randn(n, 4, generator=g)
    scales = 0.7 * n ** (-1 / 3) * torch.exp(0.3 * torch.randn(n, 3, generator=g))
    colors = torch.rand(n, 3, generator=g)
    opac = opacity[0] + (opacity[1] - opacity[0]) * torch.rand(n, generator=g)
    return [t.to(dtype).requires_grad_() for t in (means, quats, scales, colors, opac)]


def camera(width: int, height: int, dtype: torch.dtype, dist: float = 2.5):
    """OpenCV camera on the -z side looking at the origin, 40 degree horizontal FOV."""
    f = 0.5 * width / math.tan(math.radians(20))
    K = torch.tensor([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]], dtype=dtype)
    w2c = torch.eye(4, dtype=dtype)
    w2c[2, 3] = dist
    return K, w2c


def render_and_grads(params, K, w2c, width, height, backend, labels=None):
    """Render, build a loss touching rgb/alpha/depth, return (output, grads of the 5 inputs)."""
    dtype = params[0].dtype
    bg = torch.tensor([0.2, 0.5, 0.9], dtype=dtype)
    out = rasterize(*params, K, w2c, width, height, background=bg, backend=backend,
                    labels=labels, return_max_weight=True)
    g = torch.Generator().manual_seed(7)
    wts = torch.rand(height, width, 3, generator=g).to(dtype)
    loss = (out.rgb * wts).sum() + 0.1 * (out.depth ** 2).sum() + out.alpha.sum()
    return out, torch.autograd.grad(loss, params)


def rel_err(a: torch.Tensor, b: torch.Tensor) -> float:
    """max |a - b| / max |b| (b is the reference)."""
    a, b = a.detach(), b.detach()
    return float((a - b).abs().max() / b.abs().max().clamp(min=1e-12))


@pytest.mark.parametrize("dtype,tol", [(torch.float64, 1e-6), (torch.float32, 1e-4)])
@pytest.mark.parametrize("seed,n,opacity", [(0, 300, (0.05, 0.95)), (1, 500, (0.9, 1.0)),
                                            (2, 200, (0.1, 0.1))])
def test_cpu_matches_reference(dtype, tol, seed, n, opacity):
    width, height = 40, 30  # not a multiple of the tile size on purpose
    params = random_scene(n, dtype, seed, opacity)
    K, w2c = camera(width, height, dtype)
    labels = torch.randint(0, 3, (n,), generator=torch.Generator().manual_seed(seed))
    ref, gref = render_and_grads(params, K, w2c, width, height, "reference", labels)
    cpu, gcpu = render_and_grads(params, K, w2c, width, height, "cpu", labels)
    assert ref.alpha.max() > 0.5  # the scene is really in view
    for name in ("rgb", "alpha", "depth", "label_weights", "max_weight"):
        assert rel_err(getattr(cpu, name), getattr(ref, name)) < tol, name
    for name, a, b in zip(["means", "quats", "scales", "colors", "opacities"], gcpu, gref):
        assert b.abs().max() > 0, name
        assert rel_err(a, b) < tol, name


def test_reference_gradients_match_finite_differences():
    torch.manual_seed(0)
    width, height = 20, 18
    params = [p.detach().requires_grad_() for p in random_scene(12, torch.float64, 3, (0.3, 0.9))]
    K, w2c = camera(width, height, torch.float64, dist=2.0)
    wts = torch.rand(height, width, 3, dtype=torch.float64)

    def f(*p):
        out = rasterize(*p, K, w2c, width, height, backend="reference")
        return (out.rgb * wts).sum() + 0.1 * (out.depth * out.alpha).sum()

    assert torch.autograd.gradcheck(f, params, eps=1e-6, atol=1e-5, rtol=1e-4)


def test_single_gaussian_follows_3dgs_formula():
    dt = torch.float64
    K, w2c = camera(32, 32, dt)
    means = torch.tensor([[0.0, 0.0, 0.0]], dtype=dt)  # projects to the image centre
    quats = torch.tensor([[1.0, 0, 0, 0]], dtype=dt)
    scales = torch.full((1, 3), 0.2, dtype=dt)
    color = torch.tensor([[1.0, 0.5, 0.0]], dtype=dt)
    bg = torch.tensor([0.0, 0.0, 1.0], dtype=dt)
    for backend in ("reference", "cpu"):
        out = rasterize(means, quats, scales, color, torch.tensor([0.7], dtype=dt), K, w2c, 32,
                        32, background=bg, backend=backend)
        f = float(K[0, 0])
        var = (f * 0.2 / 2.5) ** 2 + 0.3  # EWA + low-pass at the image centre
        # pixel (x=10, y=15) against the projected centre (15.5, 15.5)
        alpha = 0.7 * math.exp(-0.5 * ((10 - 15.5) ** 2 + (15 - 15.5) ** 2) / var)
        expect = torch.tensor([alpha, 0.5 * alpha, 1 - alpha], dtype=dt)
        assert torch.allclose(out.rgb[15, 10], expect, atol=1e-8), backend
        assert abs(float(out.depth[15, 10]) - 2.5) < 1e-8


def test_early_termination_and_clamp():
    dt = torch.float64
    K, w2c = camera(16, 16, dt)
    n = 10
    means = torch.zeros(n, 3, dtype=dt)
    means[:, 2] = torch.linspace(-0.5, 0.5, n, dtype=dt)
    quats = torch.tensor([[1.0, 0, 0, 0]], dtype=dt).repeat(n, 1)
    scales = torch.full((n, 3), 10.0, dtype=dt)  # huge: alpha hits the 0.99 clamp everywhere
    colors = torch.rand(n, 3, dtype=dt)
    for backend in ("reference", "cpu"):
        out = rasterize(means, quats, scales, colors, torch.ones(n, dtype=dt), K, w2c, 16, 16,
                        backend=backend, return_max_weight=True)
        # two layers of alpha 0.99 bring T to 1e-4; the third would go below and is dropped
        assert torch.allclose(out.alpha, torch.full((16, 16), 1 - 1e-4, dtype=dt))
        assert torch.allclose(out.rgb[0, 0], 0.99 * colors[0] + 0.0099 * colors[1])
        assert out.visible.tolist() == [True, True] + [False] * (n - 2)


def test_label_weights_sum_to_alpha():
    params = random_scene(400, torch.float32, 5)
    K, w2c = camera(48, 32, torch.float32)
    labels = torch.randint(0, 4, (400,))
    out = rasterize(*params, K, w2c, 48, 32, labels=labels, num_labels=4)
    assert out.label_weights.shape == (32, 48, 4)
    assert torch.allclose(out.label_weights.sum(-1), out.alpha, atol=1e-5)


def test_gsplat_backend_reports_why_it_cannot_run():
    if gsplat_status() is None:
        pytest.skip("gsplat and CUDA are available here")
    params = random_scene(10, torch.float32, 0)
    K, w2c = camera(16, 16, torch.float32)
    with pytest.raises(BackendUnavailable, match="gsplat"):
        rasterize(*params, K, w2c, 16, 16, backend="gsplat")
