"""The articulated model: posing known kinematic trees reproduces the ground truth's renders, and the
gradients of the joint parameters match finite differences."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from pd2gs.articulated.model import ArticulatedGaussians, ModelError, canonical_gaussians
from pd2gs.articulated.scenes import make_scene
from pd2gs.render import rasterize
from pd2gs.synthetic import open_lid, ring_cameras

SIZE = (64, 48)
BG = torch.tensor([1.0, 1.0, 1.0])


def model_of(scene, ownership=None, dtype=torch.float32, **kw) -> ArticulatedGaussians:
    g = canonical_gaussians(scene.means, scene.quats, scene.scales, scene.colors, scene.opacities, dtype)
    return ArticulatedGaussians(g, scene.parent, scene.joint_types, scene.axes, scene.pivots, scene.values,
                                scene.labels if ownership is None else ownership, **kw)


def gt_render(scene, means, K, w2c):
    return rasterize(means, scene.quats, scene.scales, scene.colors, scene.opacities, K, w2c, *SIZE,
                     background=BG).rgb


@pytest.mark.parametrize("hard", [True, False])
def test_posing_the_lid_scene_reproduces_its_renders(hard):
    scene = make_scene("lid", n=2000)
    # soft ownership with confident logits must pose like hard ownership
    model = model_of(scene, confidence=60.0)
    if hard:
        model.harden()
    cams = ring_cameras(5, *SIZE)
    with torch.no_grad():
        for s, ang in enumerate((0.0, 20.0, 40.0, 60.0)):
            means, quats = model.pose(s)
            # ground truth posed by pd2gs.synthetic, independently of the model
            truth = open_lid(scene.means, scene.labels, ang)
            assert torch.allclose(means, truth, atol=1e-5)
            for K, w2c in cams:
                got = model.render(s, K, w2c, *SIZE, background=BG).rgb
                assert float((got - gt_render(scene, truth, K, w2c)).abs().max()) < 2e-4


def test_posing_a_chain_flap_on_lid_reproduces_its_renders():
    scene = make_scene("flap", n=2000)
    model = model_of(scene)
    model.harden()
    cams = ring_cameras(5, *SIZE)
    with torch.no_grad():
        for s in range(scene.values.shape[0]):
            truth = scene.posed_means(s)  # rsart.kinematics.joint_motion composed parent @ child
            means, _ = model.pose(s)
            assert torch.allclose(means, truth, atol=1e-5)
            for K, w2c in cams:
                got = model.render(s, K, w2c, *SIZE, background=BG).rgb
                assert float((got - gt_render(scene, truth, K, w2c)).abs().max()) < 2e-4
    # the flap really is carried by the lid: with the lid at 0 it differs from the posed chain
    vals = model.values[3].detach().clone()
    vals[0] = 0.0
    with torch.no_grad():
        moved, _ = model.pose(values=vals)
    flap = scene.labels == 2
    assert float((moved[flap] - scene.posed_means(3)[flap]).norm(dim=1).mean()) > 0.05


def test_posed_rotations_compose_body_and_gaussian_rotations():
    scene = make_scene("flap", n=300)
    q0 = torch.nn.functional.normalize(torch.randn(scene.means.shape[0], 4, generator=torch.Generator().manual_seed(1)),
                                       dim=1)
    scene.quats = q0
    model = model_of(scene)
    model.harden()
    from pd2gs.render.projection import quat_to_rotmat
    with torch.no_grad():
        _, quats = model.pose(3)
        T = np.stack(scene.body_transforms(3))[scene.labels.numpy()]
        want = torch.from_numpy(T[:, :3, :3]).float() @ quat_to_rotmat(q0)
        assert torch.allclose(quat_to_rotmat(quats), want, atol=1e-5)


def _small_soft_model(n=40, child="revolute"):
    scene = make_scene("flap", n=600)
    scene.joint_types = ["revolute", child]
    idx = torch.randperm(scene.means.shape[0], generator=torch.Generator().manual_seed(0))[:n]
    for name in ("means", "quats", "scales", "colors", "opacities", "labels"):
        setattr(scene, name, getattr(scene, name)[idx])
    logits = torch.randn(n, 3, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    model = model_of(scene, ownership=logits, dtype=torch.float64, temperature=0.7)
    with torch.no_grad():  # a generic point: off-axis-aligned joints, non-trivial values
        model.axes.add_(torch.tensor([[0.1, -0.2, 0.15], [0.05, 0.1, -0.1]], dtype=torch.float64))
        model.pivots.add_(0.03)
        model.values.add_(0.1)
    return model


def _finite_difference_check(model, loss_fn, eps=1e-6, rtol=1e-4):
    params = {"axes": model.axes, "pivots": model.pivots, "values": model.values}
    model.zero_grad()
    loss_fn().backward()
    for name, p in params.items():
        grad = p.grad.clone()
        fd = torch.zeros_like(p)
        with torch.no_grad():
            for i in range(p.numel()):
                flat = p.view(-1)
                old = float(flat[i])
                flat[i] = old + eps
                up = float(loss_fn())
                flat[i] = old - eps
                down = float(loss_fn())
                flat[i] = old
                fd.view(-1)[i] = (up - down) / (2 * eps)
        scale = float(fd.abs().max()) + 1e-12
        assert float((grad - fd).abs().max()) <= rtol * scale, (name, grad, fd)
        assert scale > 1e-6, f"{name}: the loss does not depend on it"


@pytest.mark.parametrize("child", ["revolute", "prismatic"])
def test_joint_gradients_of_the_soft_pose_match_finite_differences(child):
    model = _small_soft_model(child=child)
    g = torch.Generator().manual_seed(3)
    wm = torch.randn(40, 3, generator=g, dtype=torch.float64)
    wq = torch.randn(40, 4, generator=g, dtype=torch.float64)

    def loss():
        total = 0.0
        for s in range(model.num_states):
            m, q = model.pose(s)
            total = total + (wm * m).sum() + (wq * q).sum()
        return total

    _finite_difference_check(model, loss)


@pytest.mark.parametrize("child", ["revolute", "prismatic"])
def test_joint_gradients_through_the_rasterizer_match_finite_differences(child):
    model = _small_soft_model(child=child)
    K, w2c = ring_cameras(1, 24, 18)[0]
    target = torch.rand(18, 24, 3, generator=torch.Generator().manual_seed(4), dtype=torch.float64)

    def loss():
        out = model.render(3, K, w2c, 24, 18, background=BG, backend="reference")
        return ((out.rgb - target) ** 2).sum()

    _finite_difference_check(model, loss, eps=1e-7, rtol=1e-3)


def test_inconsistent_models_are_rejected_with_the_field_named():
    scene = make_scene("flap", n=200)
    g = canonical_gaussians(scene.means, scene.quats, scene.scales, scene.colors, scene.opacities)
    with pytest.raises(ModelError, match="parent"):
        ArticulatedGaussians(g, [-1, 2, 0], scene.joint_types, scene.axes, scene.pivots, scene.values, scene.labels)
    with pytest.raises(ModelError, match="joint_types"):
        ArticulatedGaussians(g, [-1, 0, 1], ["revolute", "ball"], scene.axes, scene.pivots, scene.values,
                             scene.labels)
    with pytest.raises(ModelError, match="ownership"):
        ArticulatedGaussians(g, [-1, 0, 1], scene.joint_types, scene.axes, scene.pivots, scene.values,
                             scene.labels[:10])
    with pytest.raises(ModelError, match="axes"):
        ArticulatedGaussians(g, [-1, 0, 1], scene.joint_types, np.zeros((2, 3)), scene.pivots, scene.values,
                             scene.labels)
