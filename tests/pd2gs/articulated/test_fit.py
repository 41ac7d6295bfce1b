"""The end-to-end articulated fit recovers the synthetic lid's joint from a perturbed start."""
from __future__ import annotations

import pytest
import torch

from pd2gs.articulated.experiment import Perturbation, joint_errors, perturbed_lid_model, run
from pd2gs.articulated.fit import FitConfig, evaluate_views, fit_articulated, temperature_at, view_loss
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


def test_ownership_warmup_holds_every_owner_before_the_joints_settle(small):
    """``ownership_warmup``: no ownership gradient step and no colour re-assignment in the first steps, then both."""
    scene, frames, masks = small
    model = perturbed_lid_model(scene, Perturbation())
    logits0, axes0 = model.ownership_logits.detach().clone(), model.axes.detach().clone()
    res = fit_articulated(model, frames, masks, FitConfig(iters=4, ownership_warmup=4, reassign_every=1,
                                                          harden=False))
    assert torch.equal(model.ownership_logits.detach(), logits0) and res.reassigned == []
    assert not torch.equal(model.axes.detach(), axes0)
    res = fit_articulated(model, frames, masks, FitConfig(iters=6, ownership_warmup=3, reassign_every=1,
                                                          harden=False))
    assert not torch.equal(model.ownership_logits.detach(), logits0)
    assert len(res.reassigned) == 2  # after step 3 and step 4 (none in the last ``reassign_every`` steps)


def test_the_held_out_loss_adds_the_fits_silhouette_term_where_masks_are_given():
    # a white lid before a white background: the silhouette sees a lid that stays shut where colour barely does
    scene = make_scene("lid", n=1200)
    scene.colors[scene.labels == 1] = 1.0
    frames, masks = render_scene(scene, views=8, size=(48, 36))
    exact = Perturbation(axis_deg=0, pivot_m=0, values_deg=0, means_m=0, colors=0, flip=0)
    truth, shut = perturbed_lid_model(scene, exact), perturbed_lid_model(scene, exact)
    with torch.no_grad():
        shut.values.zero_()
    bg = torch.ones(3)
    for m in (truth, shut):
        m.harden()
        l1 = evaluate_views(m, frames)
        assert evaluate_views(m, frames, masks=masks, silhouette=0.0) == l1
        assert evaluate_views(m, frames, masks=[None] * len(frames), silhouette=0.5) == l1
        with torch.no_grad():
            sil = [float((m.render(f.state, f.K, f.w2c, *f.size, background=bg).alpha - k).abs().mean())
                   for f, k in zip(frames, masks) if f.split == "test"]
        assert evaluate_views(m, frames, masks=masks, silhouette=0.5) == pytest.approx(l1 + 0.5 * sum(sil) / len(sil))
    gap_rgb = evaluate_views(shut, frames) - evaluate_views(truth, frames)
    gap_sil = (evaluate_views(shut, frames, masks=masks, silhouette=0.5)
               - evaluate_views(truth, frames, masks=masks, silhouette=0.5))
    assert gap_rgb > 0 and gap_sil > 2 * gap_rgb
    with pytest.raises(ValueError, match="masks"):
        evaluate_views(truth, frames, masks=masks[:3], silhouette=0.5)
