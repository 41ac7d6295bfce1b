"""Deformable field: exact identity at initialisation, quaternion algebra, part-level hook."""
from __future__ import annotations

import torch

from pd2gs.deform import DeformableField, DeformConfig, quat_multiply
from pd2gs.gaussians import init_from_bounds
from pd2gs.render.projection import quat_to_rotmat


def make_field(n=200, states=4):
    g = init_from_bounds([-0.5, -0.5, 0.0], [0.5, 0.5, 0.6], n, seed=0)
    with torch.no_grad():
        g.quats.copy_(torch.randn(n, 4))
    return DeformableField(g, states, DeformConfig(), torch.tensor([0.0, 0.0, 0.3]), 0.8)


def test_untrained_field_is_exact_identity():
    fld = make_field()
    g = fld.gaussians
    for k in range(4):
        d = fld.deform(fld.latent(k))
        assert torch.equal(d.means, g.means)
        assert torch.equal(d.log_scales, g.log_scales)
        q = g.quats / g.quats.norm(dim=-1, keepdim=True)
        assert torch.allclose(d.quats, q, atol=1e-7)
    assert torch.count_nonzero(fld.mlp.head.weight) == 0 and torch.count_nonzero(fld.mlp.head.bias) == 0


def test_quaternion_product_composes_rotations():
    a, b = torch.randn(50, 4), torch.randn(50, 4)
    a, b = a / a.norm(dim=-1, keepdim=True), b / b.norm(dim=-1, keepdim=True)
    lhs = quat_to_rotmat(quat_multiply(a, b))
    rhs = quat_to_rotmat(a) @ quat_to_rotmat(b)
    assert torch.allclose(lhs, rhs, atol=1e-5)


def test_offsets_depend_on_latent_once_trained_and_mask_limits_them():
    fld = make_field()
    with torch.no_grad():
        fld.mlp.head.weight.normal_(0, 0.1)
    d0, d1 = fld.deform(fld.latent(0)), fld.deform(fld.latent(1))
    assert not torch.allclose(d0.means, d1.means)
    mask = torch.zeros(fld.gaussians.num, dtype=torch.bool)
    mask[:50] = True
    part = fld.deform(fld.latent(1), mask=mask, base_latent=fld.latent(0))
    assert torch.allclose(part.means[:50], d1.means[:50])
    assert torch.allclose(part.means[50:], d0.means[50:])
    canon = fld.deform(fld.latent(1), mask=mask)
    assert torch.equal(canon.means[50:], fld.gaussians.means[50:])
    mid = fld.interpolate(0, 1, 0.5)
    assert torch.allclose(mid, 0.5 * (fld.latent(0) + fld.latent(1)))
