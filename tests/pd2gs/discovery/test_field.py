"""Adapting a trained model (duck-typed) to a StateField."""
import numpy as np
import pytest
import torch

from pd2gs.discovery.field import StateField, as_state_field


class FakeModel:
    state_ids = ["m0", "m3"]

    def __init__(self, n=5):
        self.n = n

    def _g(self, shift):
        return {"means": torch.zeros(self.n, 3) + shift, "quats": torch.tensor([[1.0, 0, 0, 0]]).repeat(self.n, 1),
                "scales": torch.full((self.n, 3), 0.01), "colors": torch.rand(self.n, 3),
                "opacities": torch.full((self.n, 1), 0.5, requires_grad=True)}

    def state_gaussians(self, sid):
        return self._g(0.0 if sid == "m0" else 1.0)

    def interpolate(self, a, b, t):
        return self._g(t)


def test_as_state_field_from_a_model():
    f = as_state_field(FakeModel(), ["m0", "m3"])
    assert f.means.shape == (2, 5, 3) and f.opacities.shape == (5,)
    assert np.allclose(f.means[1], 1.0)
    m, q, s = f.deform("m0", "m3", 0.25)
    assert np.allclose(m, 0.25) and q.shape == (5, 4)


def test_as_state_field_rejects_other_objects_and_bad_shapes():
    with pytest.raises(TypeError, match="state_gaussians"):
        as_state_field(object(), ["m0"])
    with pytest.raises(ValueError, match="quats"):
        StateField(["a"], np.zeros((1, 3, 3)), np.zeros((1, 2, 4)), np.ones((1, 3, 3)), np.zeros((3, 3)), np.ones(3))
