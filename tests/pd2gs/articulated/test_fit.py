"""The end-to-end articulated fit recovers the synthetic lid's joint from a perturbed start."""
from __future__ import annotations

import pytest
import torch

from pd2gs.articulated.experiment import Perturbation, joint_errors, perturbed_lid_model, run
from pd2gs.articulated.fit import FitConfig, fit_articulated, temperature_at, view_loss
from pd2gs.articulated.scenes import make_scene, render_scene


@pytest.fixture(scope="module")
def small():
    scene = make_scene("lid", n=1200)
    frames, masks = render_scene(scene, views=8, size=(48, 36))
    return scene, frames, masks


def test_a_short_fit_turns_the_axis_towards_the_truth(small):
    torch.manual_seed(0)
    scene, frames, masks = small
    model = perturbed_lid_model(scene, Perturbation())
    before = joint_errors(model, scene)
    res = fit_articulated(model, frames, masks, FitConfig(iters=100))
    after = joint_errors(model, scene)
    assert before["axis_deg"] == pytest.approx(15.0, abs=1e-3)
    assert after["axis_deg"] < 5.0
    assert after["pivot_m"] < before["pivot_m"]
    assert sum(res.losses[-20:]) < 0.5 * sum(res.losses[:20])
    assert model.hard  # hard ownership at the end


@pytest.mark.slow
def test_the_full_fit_recovers_the_axis_within_one_degree():
    torch.set_num_threads(1)
    out = run(iters=600, seed=1)  # defaults were chosen on seed 0 (docs); seed 1 is held out
    assert out["fit"]["axis_deg"] < 1.0, out
    assert out["fit"]["pivot_m"] < 0.02, out


def test_temperature_anneals_geometrically_between_the_configured_ends():
    cfg = FitConfig(iters=11, temperature_start=1.0, temperature_end=0.01)
    assert temperature_at(cfg, 0) == pytest.approx(1.0)
    assert temperature_at(cfg, 5) == pytest.approx(0.1)
    assert temperature_at(cfg, 10) == pytest.approx(0.01)


def test_silhouette_and_depth_terms_enter_the_loss_only_when_asked(small):
    scene, frames, masks = small
    model = perturbed_lid_model(scene, Perturbation())
    f, m = frames[1], masks[1]
    bg = torch.ones(3)
    with torch.no_grad():
        plain = float(view_loss(model, f, None, FitConfig(), bg))
        sil = float(view_loss(model, f, m, FitConfig(silhouette=1.0), bg))
        nosil = float(view_loss(model, f, m, FitConfig(silhouette=0.0), bg))
        depth = float(view_loss(model, f, None, FitConfig(depth=1.0), bg))
    assert nosil == pytest.approx(plain)
    assert sil > plain and depth > plain


def test_bad_fit_input_is_named(small):
    scene, frames, masks = small
    model = perturbed_lid_model(scene, Perturbation())
    with pytest.raises(ValueError, match="masks"):
        fit_articulated(model, frames, masks[:3], FitConfig(iters=1))
    with pytest.raises(ValueError, match="train"):
        fit_articulated(model, [f for f in frames if f.split == "test"], None, FitConfig(iters=1))
    with pytest.raises(ValueError, match="ref_state"):
        fit_articulated(model, frames, masks, FitConfig(iters=1, ref_state=7))


def test_joint_warmup_holds_the_geometry_still(small):
    scene, frames, masks = small
    model = perturbed_lid_model(scene, Perturbation())
    means0, axes0 = model.gaussians.means.detach().clone(), model.axes.detach().clone()
    fit_articulated(model, frames, masks, FitConfig(iters=4, joint_warmup=4, reassign_every=0))
    assert torch.equal(model.gaussians.means, means0)
    assert not torch.equal(model.axes.detach(), axes0)
    fit_articulated(model, frames, masks, FitConfig(iters=4, joint_warmup=2, reassign_every=0))
    assert not torch.equal(model.gaussians.means, means0)


WRONG_AXIS = (-0.5, 0.0, 0.8660254037844386)  # the lid's hinge axis (-x) turned 60° towards +z


def lid_started_as_a_slide_60_degrees_off(scene):
    """The lid scene's model with a start no gradient fit recovers from: wrong type, axis 60° off, pivot at
    the lid's centroid, a small slide."""
    import numpy as np

    from pd2gs.articulated.model import ArticulatedGaussians, canonical_gaussians

    g = canonical_gaussians(scene.means, scene.quats, scene.scales, scene.colors, scene.opacities)
    lid = scene.means[scene.labels == 1].double().mean(0).numpy()
    return ArticulatedGaussians(g, [-1, 0], ["prismatic"], np.array([WRONG_AXIS]), lid[None],
                                np.linspace(0, 0.05, 4)[:, None], scene.labels)


def test_the_coarse_search_turns_a_lid_started_as_a_slide_60_degrees_off_into_its_hinge():
    import math

    import numpy as np

    from pd2gs.articulated.scenes import angle_between_deg, line_distance
    from pd2gs.articulated.search import SearchConfig, search_joints

    torch.set_num_threads(1)
    scene = make_scene("lid", n=1500)
    frames, _ = render_scene(scene, views=8, size=(48, 36))
    model = lid_started_as_a_slide_60_degrees_off(scene)
    res = search_joints(model, frames, 0, SearchConfig())
    assert res.chosen[1]["changed"] and res.chosen[1]["loss_after"] < 0.5 * res.chosen[1]["loss_before"]
    assert model.joint_types == ["revolute"]
    assert angle_between_deg(model.unit_axes[0].detach(), scene.axes[0]) < 10.0
    assert line_distance(scene.pivots[0], scene.axes[0], model.pivots[0].detach()) < 0.06
    # the far value within one grid step (30°) of the truth, with the truth's sign about the found axis
    sign = float(np.sign(model.unit_axes[0].detach().double().numpy() @ scene.axes[0]))
    assert abs(sign * float(model.values[3, 0].detach()) - scene.values[3, 0]) <= math.radians(30) + 1e-6


def test_the_coarse_search_keeps_the_current_joint_when_the_held_out_views_do_not_confirm_the_new_one():
    import numpy as np

    from pd2gs.articulated.search import SearchConfig, search_joints

    torch.set_num_threads(1)
    scene = make_scene("lid", n=800)
    frames, _ = render_scene(scene, views=8, size=(40, 30))
    # the hinge found on the training views renders the held-out ones far better: taken
    m = lid_started_as_a_slide_60_degrees_off(scene)
    res = search_joints(m, frames, 0, SearchConfig())
    c = res.chosen[1]
    assert c["changed"] and c["held_out_after"] < 0.5 * c["held_out_before"] and m.joint_types == ["revolute"]
    # a gain no hypothesis can reach (the whole held-out error): the slide stays, untouched
    m = lid_started_as_a_slide_60_degrees_off(scene)
    res = search_joints(m, frames, 0, SearchConfig(min_gain_rel=1.0))
    assert not res.chosen[1]["changed"] and m.joint_types == ["prismatic"]
    assert np.allclose(m.unit_axes[0].detach().numpy(), WRONG_AXIS, atol=1e-6)
