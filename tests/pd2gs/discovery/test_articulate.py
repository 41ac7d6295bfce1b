"""Photometric articulation fit: known rigid motions rendered by the real rasterizer are recovered from a
wrong start (axis, pivot, values, even the type), and mislabelled Gaussians go back to their part."""
import dataclasses
import math

import numpy as np
import pytest
import torch

from pd2gs.discovery.articulate import FitSettings, fit_articulation
from pd2gs.discovery.field import StateField
from pd2gs.discovery.kinematics import JointEstimate
from pd2gs.render import rasterize
from pd2gs.synthetic import ring_cameras, scene_gaussians
from rsart.camera import Camera, Intrinsics
from rsart.kinematics import joint_motion

STATES = ["m0", "m1", "m2", "m3"]
W, H = 64, 48
BG = (1.0, 1.0, 1.0)
HINGE = {"axis": np.array([1.0, 0.0, 0.0]), "origin": np.array([0.0, 0.2, 0.4]), "values": [0.0, -0.35, -0.7, -1.05]}
SLIDE = {"axis": np.array([0.0, -1.0, 0.0]), "origin": np.zeros(3), "values": [0.0, 0.05, 0.1, 0.15]}


def _scene(jtype: str, n: int = 1500):
    """StateField of the synthetic base + lid moved by the true joint, the true labels and the captured views."""
    means, quats, scales, colors, opac, labels = (t.numpy().astype(np.float64) for t in scene_gaussians(n, seed=1))
    labels = labels.astype(int)
    truth = HINGE if jtype == "revolute" else SLIDE
    lid = labels == 1
    M, Q = [], []
    for v in truth["values"]:
        T = joint_motion(jtype, truth["axis"], truth["origin"], v)
        m = means.copy()
        m[lid] = means[lid] @ T[:3, :3].T + T[:3, 3]
        M.append(m)
        Q.append(quats)
    fld = StateField(list(STATES), np.stack(M), np.stack(Q), np.tile(scales, (4, 1, 1)), colors, opac)
    return fld, labels, _capture(fld), truth


def _cameras() -> list[Camera]:
    cams = []
    for K, w2c in ring_cameras(10, W, H):
        K = K.numpy()
        cams.append(Camera(Intrinsics(W, H, float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), None),
                           np.linalg.inv(w2c.numpy().astype(np.float64))))
    return cams


def _capture(fld: StateField):
    """The 'captured' training views: every state of ``fld`` rendered by the real rasterizer (uint8 RGB)."""
    f32 = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32)  # noqa: E731
    with torch.no_grad():
        return [[(c, (rasterize(f32(fld.means[k]), f32(fld.quats[k]), f32(fld.scales[k]), f32(fld.colors),
                                f32(fld.opacities), f32(c.K), f32(c.w2c), W, H,
                                background=torch.tensor(BG)).rgb.clamp(0, 1).numpy() * 255).round().astype(np.uint8))
                 for c in _cameras()] for k in range(fld.k)]


def _wrong_start(jtype: str, truth: dict) -> JointEstimate:
    """A start 25 degrees off in axis, 8 cm off in pivot, values halved (what a noisy field gives)."""
    R = joint_motion("revolute", np.array([0.0, 0.0, 1.0]), np.zeros(3), math.radians(25))[:3, :3]
    axis = R @ truth["axis"]
    vals = {s: 0.5 * v for s, v in zip(STATES, truth["values"])}
    return JointEstimate(jtype, axis, truth["origin"] + np.array([0.0, -0.08, 0.05]), vals, "bic", jtype, jtype)


def _axis_err(a, b) -> float:
    return math.degrees(math.acos(min(1.0, abs(float(np.dot(a, b)) / np.linalg.norm(a) / np.linalg.norm(b)))))


def _line_dist(o1, u1, o2, u2) -> float:
    n = np.cross(u1, u2)
    d = o2 - o1
    if np.linalg.norm(n) < 1e-6:
        return float(np.linalg.norm(np.cross(d, u1)) / np.linalg.norm(u1))
    return float(abs(d @ n) / np.linalg.norm(n))


FAST = FitSettings(iters=150, relabel=False, search_views=2)


def test_revolute_joint_recovered_from_a_wrong_start():
    fld, labels, views, truth = _scene("revolute")
    start = _wrong_start("revolute", truth)
    out, new_labels, diag = fit_articulation(fld, labels, {1: start}, views, "m0", "m3", FAST, BG)
    j = out[1]
    assert j.type == "revolute"
    assert _axis_err(j.axis, truth["axis"]) < 2.0
    assert _line_dist(j.origin, j.axis, truth["origin"], truth["axis"]) < 0.01
    sign = float(np.sign(j.axis @ truth["axis"]))
    for s, v in zip(STATES, truth["values"]):
        assert abs(sign * j.values[s] - v) < math.radians(2.0), (s, j.values[s], v)
    assert diag["loss_final"] < diag["loss_start"]
    assert np.array_equal(new_labels, labels)  # relabelling off: labels unchanged


def test_slide_recovered_and_type_corrected_from_a_revolute_start():
    fld, labels, views, truth = _scene("prismatic")
    start = _wrong_start("revolute", truth)
    out, _, diag = fit_articulation(fld, labels, {1: start}, views, "m0", "m3", FAST, BG)
    j = out[1]
    assert j.type == "prismatic", diag
    assert _axis_err(j.axis, truth["axis"]) < 2.0
    assert j.axis @ truth["axis"] > 0  # positive values in the end state fix the sign
    for s, v in zip(STATES, truth["values"]):
        assert abs(j.values[s] - v) < 0.005, (s, j.values[s], v)


def test_type_is_kept_when_choice_is_off():
    fld, labels, views, truth = _scene("prismatic")
    s = FitSettings(iters=60, relabel=False, choose_type=False, search=False)
    out, _, _ = fit_articulation(fld, labels, {1: _wrong_start("revolute", truth)}, views, "m0", "m3", s, BG)
    assert out[1].type == "revolute"


def test_relabelling_returns_mislabelled_gaussians_to_their_part():
    """With one reference state for all parts. With the lid's own (m3, the default) the outcome sits on
    the threshold: 10 or 11 of 13 returned and 0-3 base Gaussians moved, depending on the thread count
    (docs/pd2gs-parts.md, Known limits)."""
    fld, labels, views, truth = _scene("revolute")
    rng = np.random.default_rng(0)
    # Gaussians on the front half of the lid's top face: the side faces are 1-2 px thin in these 64x48
    # views, and near the hinge the lid barely moves (its closed place stays hidden under it)
    lid = np.flatnonzero((labels == 1) & (fld.means[0][:, 2] > 0.419) & (fld.means[0][:, 1] < 0.0))
    wrong = rng.choice(lid, len(lid) // 3, replace=False)
    given = labels.copy()
    given[wrong] = 0
    s = FitSettings(iters=150, search_views=2, part_ref=False)
    out, new_labels, diag = fit_articulation(fld, given, {1: _wrong_start("revolute", truth)}, views, "m0", "m3",
                                             s, BG)
    back = float(np.mean(new_labels[wrong] == 1))
    base = labels == 0
    assert back > 0.8, back
    assert np.mean(new_labels[base] == 0) > 0.95
    assert diag["relabel_changed"] > 0
    assert _axis_err(out[1].axis, truth["axis"]) < 2.0


def test_no_joints_is_a_no_op():
    fld, labels, views, _ = _scene("revolute", n=200)
    out, new_labels, diag = fit_articulation(fld, labels, {}, views, "m0", "m3", FAST, BG)
    assert out == {} and diag == {} and np.array_equal(new_labels, labels)


@pytest.mark.parametrize("bad", ["m9"])
def test_unknown_reference_state_is_named(bad):
    fld, labels, views, truth = _scene("revolute", n=200)
    with pytest.raises(KeyError, match=bad):
        fit_articulation(fld, labels, {1: _wrong_start("revolute", truth)}, views, bad, "m3", FAST, BG)


# A flap hinged on the lid (the lid's right end, x > 0.1, folding about the lid's y direction at x = 0.1):
# in the world it moves by the lid's hinge and then its own, like a door handle or a lamp's upper arm.
CHAIN = FitSettings(iters=120, relabel=False, search_views=1, choose_type=False, angle_steps=16, absorb=False,
                    pivot_steps=5)  # types have their own tests; a coarser search keeps these quick; absorbing is
# tested on its own below
FLAP = {"axis": np.array([0.0, 1.0, 0.0]), "origin": np.array([0.1, 0.0, 0.42]), "values": [0.0, 0.3, 0.6, 0.9]}


def _chained_scene(n: int = 2000):
    means, quats, scales, colors, opac, labels = (t.numpy().astype(np.float64) for t in scene_gaussians(n, seed=2))
    labels = labels.astype(int)
    labels[(labels == 1) & (means[:, 0] > 0.1)] = 2
    M, Q = [], []
    for a, b in zip(HINGE["values"], FLAP["values"]):
        T_lid = joint_motion("revolute", HINGE["axis"], HINGE["origin"], a)
        T_flap = T_lid @ joint_motion("revolute", FLAP["axis"], FLAP["origin"], b)
        m = means.copy()
        for lab, T in ((1, T_lid), (2, T_flap)):
            m[labels == lab] = means[labels == lab] @ T[:3, :3].T + T[:3, 3]
        M.append(m)
        Q.append(quats)  # isotropic Gaussians: rotation does not change them
    fld = StateField(list(STATES), np.stack(M), np.stack(Q), np.tile(scales, (4, 1, 1)), colors, opac)
    return fld, labels, _capture(fld)


@pytest.mark.parametrize("ref", ["m0", "m3"])
def test_chained_part_is_fitted_relative_to_its_parent(ref):
    """Fitted from either state's Gaussians, the joints come out in the start state's frame, zero there."""
    fld, labels, views = _chained_scene()
    # the flap's start: the world-frame estimate a centre-based fit gives (the lid's hinge, summed values)
    world = JointEstimate("revolute", HINGE["axis"], HINGE["origin"],
                          {s: v for s, v in zip(STATES, HINGE["values"])}, "bic", "revolute", "revolute")
    out, _, diag = fit_articulation(fld, labels, {1: _wrong_start("revolute", HINGE), 2: world}, views, ref, "m3",
                                    CHAIN, BG, start="m0")
    assert diag["chain_trials"]["2<-1"]["kept"], diag["chain_trials"]
    assert not diag["chain_trials"].get("1<-2", {}).get("kept", False)
    flap, lid = out[2], out[1]
    assert flap.diagnostics["parent"] == 1 and lid.diagnostics["parent"] is None
    assert _axis_err(lid.axis, HINGE["axis"]) < 2.0
    assert _axis_err(flap.axis, FLAP["axis"]) < 3.0
    assert _line_dist(flap.origin, flap.axis, FLAP["origin"], FLAP["axis"]) < 0.015
    sign = float(np.sign(flap.axis @ FLAP["axis"]))
    for s, v in zip(STATES, FLAP["values"]):  # relative to the lid, as the benchmark's chained ground truth is
        assert abs(sign * flap.values[s] - v) < math.radians(3.0), (s, flap.values[s], v)


def test_parts_on_the_base_stay_unchained():
    """Two parts hinged on the base (the lid halves, opposite hinges) are not explained better as a chain."""
    means, quats, scales, colors, opac, labels = (t.numpy().astype(np.float64) for t in scene_gaussians(2000, seed=3))
    labels = labels.astype(int)
    labels[(labels == 1) & (means[:, 1] < 0.0)] = 2
    back = {"axis": HINGE["axis"], "origin": HINGE["origin"], "values": HINGE["values"]}
    front = {"axis": -HINGE["axis"], "origin": np.array([0.0, -0.2, 0.4]), "values": [0.0, -0.3, -0.6, -0.9]}
    M = []
    for a, b in zip(back["values"], front["values"]):
        m = means.copy()
        for lab, j, v in ((1, back, a), (2, front, b)):
            T = joint_motion("revolute", j["axis"], j["origin"], v)
            m[labels == lab] = means[labels == lab] @ T[:3, :3].T + T[:3, 3]
        M.append(m)
    fld = StateField(list(STATES), np.stack(M), np.tile(quats, (4, 1, 1)), np.tile(scales, (4, 1, 1)), colors, opac)
    views = _capture(fld)
    start = {1: _wrong_start("revolute", back), 2: _wrong_start("revolute", front)}
    out, _, diag = fit_articulation(fld, labels, start, views, "m0", "m3",
                                    dataclasses.replace(CHAIN, absorb=True), BG)
    assert diag["chain_trials"], "the halves touch, so both chains are tried"
    assert not any(t["kept"] for t in diag["chain_trials"].values()), diag["chain_trials"]
    assert not diag["absorb"]["pruned"] and not diag["absorb"]["merged"], diag["absorb"]  # two real parts: both kept
    for lab, j in ((1, back), (2, front)):
        assert out[lab].diagnostics["parent"] is None
        assert _axis_err(out[lab].axis, j["axis"]) < 2.0


ABSORB = FitSettings(iters=100, relabel=False, search_views=1, choose_type=False, chain=False, angle_steps=16,
                     absorb=True, pivot_steps=5)


def test_an_over_split_part_is_merged_back():
    """The lid cut into two clusters (what a field that does not move it rigidly gives k-means): one joint
    moves both as well as two, so they merge into one part with the true hinge."""
    fld, labels, views, truth = _scene("revolute", n=1500)
    split = labels.copy()
    split[(labels == 1) & (fld.means[0][:, 0] > 0.0)] = 2
    start = {1: _wrong_start("revolute", truth), 2: _wrong_start("revolute", truth)}
    out, new_labels, diag = fit_articulation(fld, split, start, views, "m0", "m3", ABSORB, BG)
    assert len(diag["absorb"]["merged"]) == 1 and not diag["absorb"]["pruned"], diag["absorb"]
    (lab, j), = out.items()
    assert set(np.unique(new_labels[labels == 1])) == {lab}
    assert np.all(new_labels[labels == 0] == 0)
    assert _axis_err(j.axis, truth["axis"]) < 2.0
    assert _line_dist(j.origin, j.axis, truth["origin"], truth["axis"]) < 0.01


def test_a_still_cluster_joins_the_base():
    """A piece of the base labelled as a third part (a cluster of Gaussians the field jitters): held still
    it renders no worse, so it joins the static base and the lid keeps its joint."""
    fld, labels, views, truth = _scene("revolute", n=1500)
    given = labels.copy()
    piece = (labels == 0) & (fld.means[0][:, 0] > 0.1)
    given[piece] = 2
    jitter = JointEstimate("revolute", np.array([0.0, 0.0, 1.0]), fld.means[0][piece].mean(0),
                           {s: 0.02 * i for i, s in enumerate(STATES)}, "bic", "revolute", "revolute")
    out, new_labels, diag = fit_articulation(fld, given, {1: _wrong_start("revolute", truth), 2: jitter}, views,
                                             "m0", "m3", ABSORB, BG)
    assert [d["part"] for d in diag["absorb"]["pruned"]] == [2], diag["absorb"]
    assert list(out) == [1] and np.all(new_labels[piece] == 0)
    assert _axis_err(out[1].axis, truth["axis"]) < 2.0


def _hidden_tray_scene(n_base: int = 2400, n_tray: int = 500):
    """A closed box whose tray (label 1) slides out along +x: inside the box at m0, fully out at m3. Like a
    trained field, the m0 state holds the hidden tray's Gaussians at a guessed place (scrambled inside the
    box): no m0 view sees them, so nothing there fixes them."""
    from pd2gs.synthetic import _surface_points

    g = torch.Generator().manual_seed(5)
    base = _surface_points([-0.3, -0.2, 0.0], [0.3, 0.2, 0.38], n_base, g).numpy().astype(np.float64)
    tray = _surface_points([-0.2, -0.15, 0.1], [0.2, 0.15, 0.2], n_tray, g).numpy().astype(np.float64)
    means = np.concatenate([base, tray])
    labels = np.r_[np.zeros(n_base, int), np.ones(n_tray, int)]
    stripes = 0.5 + 0.5 * np.sin(14 * means[:, 0:1] + 9 * means[:, 1:2])
    tint = np.where(labels[:, None] == 0, np.array([0.8, 0.3, 0.2]), np.array([0.1, 0.5, 0.9]))
    colors = tint * (0.5 + 0.5 * stripes)
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (len(means), 1))
    scales = np.full((len(means), 3), 0.02)
    opac = np.full(len(means), 0.95)
    slide = [0.0, 0.3, 0.45, 0.6]
    true = np.stack([means + np.outer(labels == 1, [v, 0.0, 0.0]) for v in slide])
    truth_fld = StateField(list(STATES), true, np.tile(quats, (4, 1, 1)), np.tile(scales, (4, 1, 1)), colors, opac)
    views = _capture(truth_fld)
    guessed = true.copy()
    rng = np.random.default_rng(0)
    guessed[0, labels == 1] = rng.uniform([-0.25, -0.15, 0.05], [0.25, 0.15, 0.3], size=((labels == 1).sum(), 3))
    fld = StateField(list(STATES), guessed, np.tile(quats, (4, 1, 1)), np.tile(scales, (4, 1, 1)), colors, opac)
    truth = {"axis": np.array([1.0, 0.0, 0.0]), "values": slide}
    return fld, labels, views, truth


@pytest.mark.slow
def test_a_part_hidden_at_the_start_is_moved_from_the_state_that_shows_it():
    """Taken from m0, the tray's guessed Gaussians cannot reproduce it coming out; taken from the state the
    views show it best (m3), they do, and the slide comes out right in every state."""
    fld, labels, views, truth = _hidden_tray_scene()
    start = {1: JointEstimate("prismatic", np.array([0.9, 0.3, 0.1]), np.zeros(3),
                              {s: 0.5 * v for s, v in zip(STATES, truth["values"])}, "bic", "prismatic", "prismatic")}
    s = FitSettings(iters=150, relabel=False, choose_type=False, chain=False, absorb=False)
    out, _, diag = fit_articulation(fld, labels, start, views, "m0", "m3", s, BG)
    assert diag["reference_states"][1] == "m3"
    j = out[1]
    assert _axis_err(j.axis, truth["axis"]) < 2.0
    for st, v in zip(STATES, truth["values"]):
        assert abs(j.values[st] - v) < 0.01, (st, j.values[st], v)
    _, _, diag_m0 = fit_articulation(fld, labels, start, views, "m0", "m3", dataclasses.replace(s, part_ref=False), BG)
    assert diag_m0["reference_states"][1] == "m0"
    assert diag["loss_final"] < 0.8 * diag_m0["loss_final"], (diag["loss_final"], diag_m0["loss_final"])
