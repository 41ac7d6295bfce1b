"""Model selection: prune a spurious body, merge an over-segmented part, re-parent a chained child."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from pd2gs.articulated.fit import FitConfig
from pd2gs.articulated.model import ArticulatedGaussians, canonical_gaussians
from pd2gs.articulated.scenes import make_scene, render_scene
from pd2gs.articulated.search import ConsistencyViews, SearchConfig
from pd2gs.articulated.select import (SelectConfig, candidates, complexity, hard_posed_means, keep_children,
                                      rebuild, relative_joint, searched_reparent, select_model)


def gaussians_of(scene):
    return canonical_gaussians(scene.means, scene.quats, scene.scales, scene.colors, scene.opacities)


def truth_model(scene):
    return ArticulatedGaussians(gaussians_of(scene), scene.parent, scene.joint_types, scene.axes, scene.pivots,
                                scene.values, scene.labels)


def trajectories(scene):
    """Stage 1's per-state centres, here exact."""
    return np.stack([scene.posed_means(s).numpy() for s in range(scene.values.shape[0])])


def flat_flap_model(scene):
    """The flap-on-lid scene as a flat init gives it: both bodies children of the base, the flap's joint
    its world motion fitted by Kabsch (not a fixed-axis joint: the lid carries it)."""
    t, a, p, v = relative_joint(truth_model(scene), 2, 0)
    return ArticulatedGaussians(gaussians_of(scene), [-1, 0, 0], ["revolute", t], np.stack([scene.axes[0], a]),
                                np.stack([scene.pivots[0], p]), np.stack([scene.values[:, 0], v], 1), scene.labels)


def test_relative_joint_recovers_the_flaps_joint_on_the_lid():
    scene = make_scene("flap", n=900)
    t, axis, pivot, values = relative_joint(truth_model(scene), 2, 1)
    assert t == "revolute"
    assert abs(float(axis @ scene.axes[1])) > 1 - 1e-6
    np.testing.assert_allclose(values, scene.values[:, 1], atol=1e-5)
    d = pivot - scene.pivots[1]
    assert np.linalg.norm(d - scene.axes[1] * (d @ scene.axes[1])) < 1e-4


def test_rebuild_reparents_and_merges_without_changing_the_truths_poses():
    scene = make_scene("flap", n=900)
    flat = flat_flap_model(scene)
    chained = rebuild(flat, [0, 1, 2], [-1, 0, 1], {2: relative_joint(flat, 2, 1, trajectories=trajectories(scene))})
    assert chained.parent == [-1, 0, 1]
    chained.harden()
    for s in range(4):
        assert torch.allclose(chained.pose(s)[0], scene.posed_means(s), atol=1e-4)
    merged = rebuild(flat, [0, 1, 1], [-1, 0, 0])
    assert merged.num_bodies == 2
    # soft weights of merged bodies add up
    w_flat, w_merged = flat.weights(), merged.weights()
    assert torch.allclose(w_merged[:, 1], w_flat[:, 1] + w_flat[:, 2], atol=1e-6)
    # edits offered: prune each leaf, merge the siblings once, re-parent each under the other
    edits = sorted(e["edit"] for e, _ in candidates(flat, trajectories=trajectories(scene)))
    # swaps to prismatic come twice: read off stage 1's trajectories and off the model's own posed motion
    assert edits == ["merge", "prune", "prune", "reparent", "reparent", "swap", "swap", "swap", "swap"]
    # with the count given, the edits that change it are not offered
    kept = sorted(e["edit"] for e, _ in candidates(flat, trajectories=trajectories(scene), keep_count=True))
    assert kept == ["reparent", "reparent", "swap", "swap", "swap", "swap"]


@pytest.fixture(scope="module")
def cfg():
    return SelectConfig(refit=FitConfig(iters=80))


@pytest.mark.slow
def test_selection_prunes_a_spurious_body_on_a_one_part_scene(cfg):
    torch.set_num_threads(1)
    scene = make_scene("static", n=1200)
    frames, masks = render_scene(scene, views=8, size=(48, 36))
    top = (scene.means[:, 2] > 0.3).long()
    model = ArticulatedGaussians(gaussians_of(scene), [-1, 0], ["revolute"], [[1.0, 0, 0]], [[0, 0.2, 0.4]],
                                 [[0.0], [0.01], [0.02], [0.0]], top)
    sel = select_model(model, frames, masks, cfg, trajectories(scene))
    assert sel.model.num_bodies == 1, sel.log


@pytest.mark.slow
def test_selection_merges_an_over_segmented_lid_into_one_part(cfg):
    torch.set_num_threads(1)
    scene = make_scene("lid", n=1200)
    frames, masks = render_scene(scene, views=8, size=(48, 36))
    lab = scene.labels.clone()
    lab[(lab == 1) & (scene.means[:, 0] > 0.1)] = 2
    model = ArticulatedGaussians(gaussians_of(scene), [-1, 0, 0], ["revolute"] * 2, np.tile(scene.axes, (2, 1)),
                                 np.tile(scene.pivots, (2, 1)), np.tile(scene.values, (1, 2)), lab)
    sel = select_model(model, frames, masks, cfg, trajectories(scene))
    assert sel.model.num_bodies == 2, sel.log


@pytest.mark.slow
def test_selection_merges_a_lid_cut_into_eight_pieces_past_the_old_fixed_cap(cfg):
    """Seven merges are needed; the rounds scale with the bodies entering selection (a fixed 6 used to stop
    drawer-0000's seven bodies at three)."""
    torch.set_num_threads(1)
    scene = make_scene("lid", n=1200)
    frames, masks = render_scene(scene, views=8, size=(48, 36))
    lab = scene.labels.clone()
    lid = torch.nonzero(lab == 1).squeeze(1)
    for i, piece in enumerate(torch.chunk(lid[torch.argsort(scene.means[lid, 0])], 8)):  # 8 slices along x
        lab[piece] = 1 + i
    k = int(lab.max())
    assert k == 8 and all(int((lab == b).sum()) > 30 for b in range(1, 9))
    model = ArticulatedGaussians(gaussians_of(scene), [-1] + [0] * k, ["revolute"] * k,
                                 np.tile(scene.axes, (k, 1)), np.tile(scene.pivots, (k, 1)),
                                 np.tile(scene.values, (1, k)), lab)
    # one re-fit per round, and a short one (merges of exact pieces render as well as built): the rounds are
    # the subject, and this was the suite's slowest test (248 s with the module's config)
    short = dataclasses.replace(cfg, refit=FitConfig(iters=40), refit_top=1, type_check=False)
    sel = select_model(model, frames, masks, short, trajectories(scene))
    assert sel.model.num_bodies == 2, [(e["edit"], e.get("score")) for e in sel.log if e.get("chosen")]
    assert sum(1 for e in sel.log if e.get("chosen")) == 7  # one merge per round, past the old cap of 6


@pytest.fixture(scope="module")
def flap_views():
    """The flap-on-lid scene (1200 Gaussians) and its renders, shared by the selection tests on it."""
    torch.set_num_threads(1)
    scene = make_scene("flap", n=1200)
    return (scene, *render_scene(scene, views=8, size=(48, 36)))


@pytest.mark.slow
def test_selection_hangs_the_flap_on_the_lid(cfg, flap_views):
    scene, frames, masks = flap_views
    sel = select_model(flat_flap_model(scene), frames, masks, cfg, trajectories(scene))
    assert sel.model.parent == [-1, 0, 1], sel.log


def chained_flap_with_a_flat_piece(scene):
    """The flap-on-lid truth (flap hung on the lid) plus a third body: a third of the flap's Gaussians as a
    child of the base, moved by the flap's world motion (what a flat init leaves once the rest of the flap
    has been re-parented onto the lid: desk_lamp-0001, docs/pd2gs-experiments.md, twenty-fifth entry)."""
    lab = scene.labels.clone()
    flap = torch.nonzero(lab == 2).squeeze(1)
    lab[flap[torch.argsort(scene.means[flap, 0])][: len(flap) // 3]] = 3
    t, a, p, v = relative_joint(truth_model(scene), 2, 0)
    return ArticulatedGaussians(gaussians_of(scene), [-1, 0, 1, 0], list(scene.joint_types) + [t],
                                np.vstack([scene.axes, a]), np.vstack([scene.pivots, p]),
                                np.hstack([scene.values, np.asarray(v)[:, None]]), lab)


def test_a_swap_of_the_lids_type_re_joints_the_flap_it_carries():
    """The lid made a slide and back into its hinge: with the flap re-jointed to the lid's new motion each
    time, the flap's angles are the truth's again; dragged along, they are off by the lid's angle."""
    scene = make_scene("flap", n=600)
    truth = truth_model(scene)
    ident, parent = [0, 1, 2], list(truth.parent)
    slide = relative_joint(truth, 1, 0, trajectories=trajectories(scene), joint_type="prismatic")
    slid = keep_children(truth, rebuild(truth, ident, parent, {1: slide}), 1, 0)
    hinge = ("revolute", scene.axes[0], scene.pivots[0], scene.values[:, 0])
    dragged = rebuild(slid, ident, parent, {1: hinge})
    back = keep_children(slid, dragged, 1, 0)

    def flap_angles(m):  # the flap's values about the truth's axis direction
        sign = float(np.sign(m.unit_axes[1].detach().double().numpy() @ scene.axes[1]))
        return sign * m.values[:, 1].detach().double().numpy()

    assert back.joint_types == ["revolute", "revolute"] and back.parent == [-1, 0, 1]
    assert np.abs(flap_angles(back) - scene.values[:, 1]).max() < 0.01
    assert np.abs(flap_angles(dragged) - scene.values[:, 1]).max() > 0.5
    assert keep_children(truth, dragged, 2, 0) is dragged  # a body without children: nothing to re-joint
    # the re-jointed flap is posed from its parent's new motion, not the old one
    flap = (truth.labels() == 2).numpy()
    assert np.abs(hard_posed_means(back)[:, flap] - hard_posed_means(dragged)[:, flap]).max() > 0.05


def test_a_leaf_may_merge_into_a_body_that_is_not_its_sibling():
    """The flat piece of the flap can join the chained flap: merges are offered into any body but the leaf's
    parent (that one is a prune), and the merged model poses the piece as the truth does."""
    scene = make_scene("flap", n=900)
    model = chained_flap_with_a_flat_piece(scene)
    merges = {(e["body"], e["into"]): m for e, m in candidates(model, trajectories=trajectories(scene))
              if e["edit"] == "merge"}
    assert (3, 2) in merges and (3, 1) in merges  # until 2026-11-29 only siblings: (3, 2) was not offered
    assert all(into != model.parent[b] for b, into in merges)
    merged = merges[(3, 2)]
    assert merged.parent == [-1, 0, 1]
    merged.harden()
    for s in range(4):
        assert torch.allclose(merged.pose(s)[0], scene.posed_means(s), atol=1e-4)


@pytest.mark.slow
def test_selection_merges_the_flat_piece_into_the_chained_flap(cfg, flap_views):
    scene, frames, masks = flap_views
    sel = select_model(chained_flap_with_a_flat_piece(scene), frames, masks, cfg, trajectories(scene))
    chosen = [(e["edit"], e.get("body"), e.get("into")) for e in sel.log if e.get("chosen")]
    assert sel.model.parent == [-1, 0, 1], chosen
    # the flap on the chained body. Which merge selection takes is decided by the 80-step re-fit within its
    # noise: on a Zen 5 the merge into the flap won (the whole flap on body 2); on an Intel Xeon (2026-12-06)
    # the merge into the lid re-fitted 1.2e-4 better (0.00845 against 0.00857, with a penalty of 1.9e-4;
    # as built the flap ranked first, 0.00869 against 0.00886) and the re-fit's soft ownership then brought
    # three quarters of the piece back onto the flap (91.5 %). Where a merge into the lid or a prune leaves
    # the piece, 67 % of the flap is on body 2.
    lab = sel.model.labels()
    assert (lab[scene.labels == 2] == 2).float().mean() > 0.9, chosen


@pytest.mark.slow
def test_the_searched_re_parent_finds_the_flaps_joint_where_stage_1_moved_the_flap_halfway():
    """Stage 1 moved the flap's Gaussians only halfway (a field that moves part of a part, as on stand-0002's
    holder): the flap's joint relative to the lid read off those trajectories is far off. The coarse search,
    posing every hypothesis with the lid's motion, finds it from the images."""
    torch.set_num_threads(1)
    scene = make_scene("flap", n=1200, flap_deg=(0.0, 30.0, 60.0, 90.0))  # one ramp, as the pd2gs protocol
    frames, masks = render_scene(scene, views=8, size=(48, 36))
    flat = flat_flap_model(scene)
    traj = trajectories(scene)
    flap = (scene.labels == 2).numpy()
    traj[:, flap] = traj[0, flap] + 0.5 * (traj[:, flap] - traj[0, flap])
    _, _, _, v_traj = relative_joint(flat, 2, 1, trajectories=traj)
    assert np.abs(v_traj - scene.values[:, 1]).max() > np.radians(10.0)
    sc = SearchConfig()
    views = ConsistencyViews(frames, masks, 4, "train", sc.views_per_state, sc.tau_px)
    chained = searched_reparent(flat, 2, 1, 0, views, sc)
    assert chained.parent == [-1, 0, 1]
    assert chained.joint_types[1] == "revolute"
    axis = chained.unit_axes[1].detach().double().numpy()
    assert abs(float(axis @ scene.axes[1])) > np.cos(np.radians(2.0))
    values = chained.values[:, 1].detach().double().numpy() * np.sign(float(axis @ scene.axes[1]))
    np.testing.assert_allclose(values, scene.values[:, 1], atol=np.radians(3.0))


def test_selection_without_held_out_views_is_refused():
    scene = make_scene("lid", n=300)
    frames, masks = render_scene(scene, views=4, size=(32, 24))
    train = [f for f in frames if f.split == "train"]
    with pytest.raises(ValueError, match="held-out"):
        select_model(truth_model(scene), train, None, SelectConfig(refit=FitConfig(iters=1)))


def test_selection_swaps_a_lid_started_as_a_drawer_to_revolute():
    torch.set_num_threads(1)
    scene = make_scene("lid", n=1200)
    frames, masks = render_scene(scene, views=8, size=(48, 36))
    t, axis, pivot, values = relative_joint(truth_model(scene), 1, 0, trajectories=trajectories(scene),
                                            joint_type="prismatic")
    assert t == "prismatic"
    model = ArticulatedGaussians(gaussians_of(scene), [-1, 0], [t], axis[None], pivot[None], values[:, None],
                                 scene.labels)
    sel = select_model(model, frames, masks, SelectConfig(refit=FitConfig(iters=80)), trajectories(scene))
    assert sel.model.joint_types == ["revolute"], sel.log
    d = sel.model.unit_axes[0].detach().numpy()
    assert abs(float(d @ scene.axes[0])) > np.cos(np.radians(1.0))


def test_selection_turns_a_far_hinge_imitating_the_trays_slide_into_a_slide():
    """A hinge 3 m away moves the tray almost as its slide does; it renders no better, costs more, and the
    slide read off the model's own posed motion replaces it."""
    torch.set_num_threads(1)
    scene = make_scene("tray", n=1200)
    frames, masks = render_scene(scene, views=8, size=(48, 36))
    R = 3.0
    slide = scene.axes[0]                                  # -y
    hinge_axis = np.array([-1.0, 0.0, 0.0])                # perpendicular to the slide
    pivot = scene.pivots[0] + R * np.array([0.0, 0.0, 1.0])  # far above: the tray swings along -y
    angles = np.arcsin(scene.values[:, 0] / R)             # so the tray's centre moves by the slide's values
    g = gaussians_of(scene)
    model = ArticulatedGaussians(g, [-1, 0], ["revolute"], hinge_axis[None], pivot[None], angles[:, None],
                                 scene.labels)
    # sign: rotating about -x by a positive angle moves a point below the pivot towards -y
    assert torch.allclose(model.pose(3)[0][scene.labels == 1].mean(0)[1],
                          scene.posed_means(3)[scene.labels == 1].mean(0)[1], atol=0.02)
    # stage 1 moved the tray only halfway (a field that moves part of a part): the slide read off those
    # trajectories is half the truth; the one read off the model's own posed motion is right
    traj = trajectories(scene)
    tray = (scene.labels == 1).numpy()
    traj[:, tray] = traj[0, tray] + 0.5 * (traj[:, tray] - traj[0, tray])
    sel = select_model(model, frames, masks, SelectConfig(refit=FitConfig(iters=80)), traj)
    assert sel.model.joint_types == ["prismatic"], sel.log
    chosen = [e for e in sel.log if e.get("chosen")]
    assert chosen and chosen[0]["edit"] == "swap" and chosen[0]["from"] == "posed", sel.log
    assert abs(float(sel.model.unit_axes[0].detach() @ torch.as_tensor(slide, dtype=torch.float32))) > 0.99


def test_the_type_phase_re_fits_a_swap_that_screening_dropped():
    """With the structure rounds re-fitting no candidate at all (``refit_top=0``), the far hinge can only
    become a slide in the type phase, where every swap is re-fitted unscreened."""
    torch.set_num_threads(1)
    scene = make_scene("tray", n=1200)
    frames, masks = render_scene(scene, views=8, size=(48, 36))
    R = 3.0
    pivot = scene.pivots[0] + R * np.array([0.0, 0.0, 1.0])
    model = ArticulatedGaussians(gaussians_of(scene), [-1, 0], ["revolute"], np.array([[-1.0, 0.0, 0.0]]),
                                 pivot[None], np.arcsin(scene.values[:, :1] / R), scene.labels)
    sel = select_model(model, frames, masks, SelectConfig(refit=FitConfig(iters=80), refit_top=0),
                       trajectories(scene))
    assert sel.model.joint_types == ["prismatic"], sel.log
    chosen = [e for e in sel.log if e.get("chosen")]
    assert [(e["edit"], e["phase"]) for e in chosen] == [("swap", "type")], sel.log
    slide = torch.as_tensor(scene.axes[0], dtype=torch.float32)
    assert abs(float(sel.model.unit_axes[0].detach() @ slide)) > 0.99
    off = select_model(model, frames, masks, SelectConfig(refit=FitConfig(iters=80), refit_top=0,
                                                          type_check=False), trajectories(scene))
    assert off.model.joint_types == ["revolute"], off.log


@pytest.mark.slow
def test_selection_keeps_the_flat_tree_of_two_coaxial_half_lids(cfg):
    """Hanging one half lid on the other renders exactly as the flat tree (same hinge line): the truth stays
    as it is. Every round also re-fits the incumbent with the candidates' budget ("keep"), and an edit is
    taken only when it beats that re-fitted incumbent (measured before: woven_basket-0000's right lid was
    hung on the left one after gaining from its extra re-fit alone, doubling its reported motion)."""
    torch.set_num_threads(1)
    scene = make_scene("twin", n=1200)
    assert (scene.labels == 1).sum() > 50 and (scene.labels == 2).sum() > 50
    frames, masks = render_scene(scene, views=8, size=(48, 36))
    model = truth_model(scene)
    offered = [e for e, c in candidates(model, trajectories=trajectories(scene)) if e["edit"] == "reparent"]
    assert offered  # the equivalent tree is on offer ...
    sel = select_model(model, frames, masks, cfg, trajectories(scene))
    assert sel.model.parent == [-1, 0, 0], sel.log  # ... and not taken
    assert sel.model.joint_types == ["revolute", "revolute"], sel.log
    keeps = [e for e in sel.log if e["edit"] == "keep"]
    assert keeps and keeps[-1]["score"] <= sel.log[0]["score"]  # the incumbent itself re-fitted
    assert sel.score == pytest.approx(keeps[-1]["score"])


@pytest.mark.slow
def test_selection_moves_a_spurious_chain_link_back_onto_the_base(cfg):
    """Two half lids on one hinge line, the second hung on the first (its relative turn read off the truth):
    the chain renders exactly as the flat tree and costs a unit more, so selection moves it back onto the
    base, with the joint read off its centres in the world. Before, a re-parent never offered the base, so a
    chain selection took in one round could not be undone in a later one."""
    torch.set_num_threads(1)
    scene = make_scene("twin", n=1200)
    frames, masks = render_scene(scene, views=8, size=(48, 36))
    truth = truth_model(scene)
    chained = rebuild(truth, [0, 1, 2], [-1, 0, 1], {2: relative_joint(truth, 2, 1, trajectories=trajectories(scene))})
    chained.harden()
    for s in range(4):
        assert torch.allclose(chained.pose(s)[0], scene.posed_means(s), atol=1e-4)
    onto_base = [e for e, _ in candidates(chained, trajectories=trajectories(scene))
                 if e["edit"] == "reparent" and e["parent"] == 0]
    assert [e["body"] for e in onto_base] == [2]
    sel = select_model(chained, frames, masks, cfg, trajectories(scene))
    chosen = [(e["edit"], e.get("parent"), e.get("score")) for e in sel.log if e.get("chosen")]
    assert sel.model.parent == [-1, 0, 0], chosen
    assert sel.model.joint_types == ["revolute", "revolute"], sel.log
    axis = sel.model.unit_axes[1].detach().double().numpy()
    assert abs(float(axis @ scene.axes[1])) > np.cos(np.radians(2.0))
    np.testing.assert_allclose(np.abs(sel.model.values[:, 1].detach().double().numpy()), scene.values[:, 1], atol=0.05)


def test_a_chain_link_costs_one_penalty_unit_more_than_the_flat_tree():
    """The flap on the base and the flap on the lid have the same joints; the chain claims one dependency
    more, so where both render alike the flat tree wins (woven_basket-0000's lids side by side)."""
    scene = make_scene("flap", n=300)
    flat = flat_flap_model(scene)
    chained = rebuild(flat, [0, 1, 2], [-1, 0, 1], {2: relative_joint(flat, 2, 1, trajectories=trajectories(scene))})
    assert flat.joint_types == chained.joint_types == ["revolute", "revolute"]
    assert complexity(flat) == 4
    assert complexity(chained) == complexity(flat) + 1
