"""The deformation network's latent-as-bias evaluation equals the plain concatenated input."""
from __future__ import annotations

import pytest
import torch

from pd2gs.deform import DeformConfig, DeformMLP


@pytest.mark.parametrize("activation", ["relu", "leaky"])
def test_forward_split_equals_forward_on_concatenated_input(activation):
    torch.manual_seed(0)
    cfg = DeformConfig(activation=activation, leaky_slope=0.05)
    mlp = DeformMLP(cfg).double()
    with torch.no_grad():
        mlp.head.weight.normal_(0, 0.1)
        mlp.head.bias.normal_(0, 0.1)
    n, d = 300, 3 + 6 * cfg.pe_freqs + 7
    feat = torch.randn(n, d, dtype=torch.float64, requires_grad=True)
    latent = torch.randn(cfg.latent_dim, dtype=torch.float64, requires_grad=True)
    w = torch.randn(n, 10, dtype=torch.float64)
    split = mlp.forward_split(feat, latent, chunk=128)  # three chunks, the last one partial
    full = mlp(torch.cat([feat, latent.expand(n, -1)], dim=1))
    assert torch.allclose(split, full, rtol=0, atol=1e-12)
    params = [feat, latent] + list(mlp.parameters())
    g_split = torch.autograd.grad((split * w).sum(), params)
    g_full = torch.autograd.grad((full * w).sum(), params)
    for a, b in zip(g_split, g_full):
        assert b.abs().max() > 0
        assert torch.allclose(a, b, rtol=0, atol=1e-10)


def test_unknown_activation_is_named():
    with pytest.raises(ValueError, match="activation"):
        DeformConfig(activation="gelu")
