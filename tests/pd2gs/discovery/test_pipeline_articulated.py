"""The articulated discovery mode's own steps (views, posing, joints) and the mode end to end on the small
ray-cast cabinet with a 'perfect' field (exact geometry, flat colours the fit must learn)."""
import dataclasses

import numpy as np
import pytest
import torch

import rsart
from fixture_object import build_object, perfect_field
from pd2gs.articulated.fit import FitConfig
from pd2gs.articulated.model import ArticulatedGaussians, canonical_gaussians
from pd2gs.articulated.scenes import angle_between_deg, line_distance, make_scene
from pd2gs.discovery import DiscoveryConfig
from pd2gs.discovery.pipeline import discover, method_block, model_joints, posed_field, training_views
from pd2gs.discovery.submission import write_submission
from rsart.evaluation import load_ground_truth, read_submission, score_submission

STATES = ["m0", "m1", "m2", "m3"]


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("disc-art")
    build_object(root, n_views=10)
    return root


def test_training_views_keep_the_split_scale_the_cameras_and_give_silhouettes(data):
    obj = rsart.load(data / "cabinet-0000")
    cfg = DiscoveryConfig(fit_max_side=48)
    frames, masks = training_views(obj, STATES, cfg)
    views = [v for s in STATES for v in obj.states[s].views]
    assert len(frames) == len(masks) == len(views)
    # this object has no held-out views: every fifth view of each state is lent to model selection
    assert {v.split for v in views} == {"train"}
    per_state = [[f.split for f in frames if f.state == k] for k in range(4)]
    assert all(sp == ["test" if i % 5 == 4 else "train" for i in range(len(sp))] for sp in per_state)
    assert sorted({f.state for f in frames}) == [0, 1, 2, 3]
    f, v = frames[0], views[0]
    assert max(f.size) == 48 and f.depth is None
    s = 48 / max(v.camera.width, v.camera.height)
    assert float(f.K[0, 0]) == pytest.approx(v.camera.K[0, 0] * s, rel=0.02)
    m = masks[0]
    assert tuple(m.shape) == (f.size[1], f.size[0]) and set(np.unique(m.numpy())) <= {0.0, 1.0}
    assert 0 < float(m.mean()) < 1
    _, none = training_views(obj, STATES, DiscoveryConfig(fit_max_side=48, fit_silhouette=0.0))
    assert all(x is None for x in none)
    with_depth, _ = training_views(obj, STATES, DiscoveryConfig(fit_max_side=48, fit_depth=1.0))
    assert with_depth[0].depth is not None and float(with_depth[0].depth.max()) > 0


def coloured(fld, obj):
    """The perfect field with each Gaussian's colour read from the captured views of every state where it is
    visible there (its depth matches the view's depth within 1 cm; median over views), as stage 1, trained
    on every state, learns it."""
    samples = [[] for _ in range(fld.n)]
    for k, state in enumerate(fld.state_ids):
        x = fld.means[k]
        for v in obj.states[state].views:
            cam = v.camera
            xc = x @ cam.w2c[:3, :3].T + cam.w2c[:3, 3]
            uv = xc[:, :2] / xc[:, 2:3] @ cam.K[:2, :2].T + cam.K[:2, 2]
            u, w = np.round(uv[:, 0]).astype(int), np.round(uv[:, 1]).astype(int)
            ok = (xc[:, 2] > 0) & (u >= 0) & (u < cam.width) & (w >= 0) & (w < cam.height)
            depth, rgb = v.depth, v.rgb
            for i in np.flatnonzero(ok):
                if abs(depth[w[i], u[i]] - xc[i, 2]) < 0.01:
                    samples[i].append(rgb[w[i], u[i]] / 255.0)
    fld.colors = np.array([np.median(c, axis=0) if c else fld.colors[i] for i, c in enumerate(samples)])
    return fld


def _truth(scene):
    g = canonical_gaussians(scene.means, scene.quats, scene.scales, scene.colors, scene.opacities)
    return ArticulatedGaussians(g, scene.parent, scene.joint_types, scene.axes, scene.pivots, scene.values,
                                scene.labels)


def test_posed_field_and_joints_of_a_known_chain():
    scene = make_scene("flap", n=900)
    model = _truth(scene)
    fld = posed_field(model, STATES)
    assert np.array_equal(fld.labels, scene.labels.numpy())
    for k in range(4):
        np.testing.assert_allclose(fld.means[k], scene.posed_means(k).numpy(), atol=1e-5)
    m, _, _ = fld.deform("m1", "m3", 1.0)  # unseen states pose interpolated joint values; t=1 is m3
    np.testing.assert_allclose(m, fld.means[3], atol=1e-5)
    mid, _, _ = fld.deform("m0", "m3", 0.5)
    assert not np.allclose(mid, fld.means[0], atol=1e-3) and not np.allclose(mid, fld.means[3], atol=1e-3)
    joints = model_joints(model, STATES, "m0", "m3")
    lid, flap = joints[1], joints[2]
    assert lid.diagnostics["parent"] == 0 and flap.diagnostics["parent"] == 1
    for jf, b in ((lid, 0), (flap, 1)):
        assert jf.type == "revolute" and jf.type_bic == "revolute"
        assert angle_between_deg(jf.axis, scene.axes[b]) < 1e-3
        assert line_distance(scene.pivots[b], scene.axes[b], jf.origin) < 1e-5
        # values relative to m0, signed so m3 is positive, relative to the parent (the flap's own angle)
        sign = float(np.sign(jf.axis @ scene.axes[b]))
        want = scene.values[:, b] - scene.values[0, b]
        assert jf.values["m3"] > 0
        np.testing.assert_allclose([sign * jf.values[s] for s in STATES], want, atol=1e-5)


def test_joints_are_written_at_the_start_when_the_canonical_state_is_the_end():
    """canonical="end": the model's canonical geometry is the end state's and its values are 0 there; the
    submission still gives axes and pivots in the world frame at the start and values 0 there."""
    scene = make_scene("flap", n=900)
    truth = _truth(scene)
    truth.harden()
    with torch.no_grad():
        bp = truth.body_poses(3)
        means, quats = truth.pose(3)
        g = canonical_gaussians(means.numpy(), quats.numpy(), scene.scales, scene.colors, scene.opacities)
        # each joint in its parent's canonical frame, now the parent posed at m3
        axes = np.stack([(bp.R[scene.parent[b + 1]] @ torch.as_tensor(scene.axes[b], dtype=bp.R.dtype)).numpy()
                         for b in range(2)])
        pivots = np.stack([(bp.R[scene.parent[b + 1]] @ torch.as_tensor(scene.pivots[b], dtype=bp.R.dtype)
                            + bp.t[scene.parent[b + 1]]).numpy() for b in range(2)])
    model = ArticulatedGaussians(g, scene.parent, scene.joint_types, axes, pivots,
                                 scene.values - scene.values[3], scene.labels)
    fld = posed_field(model, STATES)
    for k in range(4):
        np.testing.assert_allclose(fld.means[k], scene.posed_means(k).numpy(), atol=1e-5)
    for b, jf in model_joints(model, STATES, "m0", "m3").items():
        assert angle_between_deg(jf.axis, scene.axes[b - 1]) < 1e-3
        assert line_distance(scene.pivots[b - 1], scene.axes[b - 1], jf.origin) < 1e-5
        sign = float(np.sign(jf.axis @ scene.axes[b - 1]))
        want = scene.values[:, b - 1] - scene.values[0, b - 1]
        np.testing.assert_allclose([sign * jf.values[s] for s in STATES], want, atol=1e-5)


@pytest.mark.slow
def test_articulated_discovery_end_to_end_scores(data, tmp_path):
    torch.set_num_threads(1)
    obj = rsart.load(data / "cabinet-0000")
    fld, _ = perfect_field(obj.twin, obj.meta, STATES, n=3000, jitter=0.002)
    fld = coloured(fld, obj)
    bg = tuple(float(c) for c in obj.states["m0"].views[0].rgb[0, 0] / 255.0)  # the views' plain background
    cfg = DiscoveryConfig(fit_iters=300, select_iters=60, final_iters=150, polish_iters=150, mesh_views=6,
                          fit_max_side=64, background=bg)
    res = discover(fld, obj, cfg)
    d = res.diagnostics
    assert d["mode"] == "articulated" and d["fit"]["loss_first_last"][1] < d["fit"]["loss_first_last"][0]
    gt = load_ground_truth(data)
    sub = write_submission({obj.id: res}, tmp_path / "sub", method_block(cfg, 4), {"name": "disc-test", "version": "1"})
    parsed, problems = read_submission(sub, gt)
    assert problems == []
    m = score_submission(parsed, gt)[0]["cabinet-0000"]["metrics"]
    assert method_block(cfg)["discovery"]["mode"] == "articulated"
    assert len(res.parts) >= 2 and all(p.joint is not None for p in res.parts if p.label > 0)
    accurate = (m["count_acc"] == 1.0 and m["type_acc"] == 1.0 and set(d["tree"].values()) == {"static"} and m["axis_ang"] < 1.0
                and m["axis_pos"] < 0.1 and m["part_motion_rev"] < 2.0 and m["part_motion_pri"] < 0.01)
    if not accurate:  # a known failure, kept visible (docs/pd2gs-parts.md, "Known limits")
        # measured: with ownership held at the (near-perfect) init, the fit still turns the door 20-32° away
        # from a 0.3° start at 64 and at 128 px, and a 4-views-per-step fit ends 57° off with a lower train
        # and held-out L1 than the true joints held fixed: the fixture's views (the door covers a few dozen
        # pixels) do not pin the door's axis once the geometry may adapt. Measured 2026-11-27: with the start
        # as canonical state the door ends a slide hung on the drawer (count right by accident); with the widest
        # state (the default) selection prunes the door into the base (count 1 of 2)
        pytest.xfail(f"issue 21: on this small fixture the views do not pin the door's axis (a fit 57° off renders "
                     f"the views better than the truth): tree {d['tree']}, count acc {m['count_acc']:.0f}, "
                     f"type acc {m['type_acc']:.2f}, "
                     f"Axis Ang {m.get('axis_ang')}°, Part Motion {m.get('part_motion_rev')}° (None: no matched hinge)")


def initialised_cabinet(data, starts: str, canonical: str = "start"):
    """The cabinet's near-exact field (2000 Gaussians, 2 mm jitter) through stage1, training_views and
    initialise, at 64 px, one thread. The step tests below were measured with the start canonical (with the
    end state's, the search step of the next test leaves the drawer 2.2 degrees off instead of within 2)."""
    from pd2gs.discovery import pipeline as P

    torch.set_num_threads(1)
    obj = rsart.load(data / "cabinet-0000")
    fld, _ = perfect_field(obj.twin, obj.meta, STATES, n=2000, jitter=0.002)
    fld = coloured(fld, obj)
    bg = tuple(float(c) for c in obj.states["m0"].views[0].rgb[0, 0] / 255.0)
    d = P.stage1(fld, obj, DiscoveryConfig(fit_max_side=64, background=bg, starts=starts, canonical=canonical))
    d.frames, d.masks = P.training_views(d.obj, d.states, d.cfg)
    P.initialise(d)
    return d


def test_the_widest_state_is_canonical_and_joints_are_still_written_from_the_start(data):
    """canonical="widest": the cabinet opens its door and drawer over m0..m3, so m3 covers the most pixels and
    becomes the canonical state (values 0 there); the joints the submission writes start at 0 in m0."""
    d = initialised_cabinet(data, "kabsch", canonical="widest")
    area = d.diag["canonical"]["mask_area"]
    assert d.diag["canonical"]["state"] == "m3" and area["m3"] > area["m0"]
    assert d.ref_index == 3 and float(d.model.values[3].abs().max()) == 0.0
    assert float(d.model.values[0].abs().max()) > 0.0
    for jf in model_joints(d.model, d.states, d.start, d.end).values():
        assert jf.values["m0"] == 0.0 and jf.values["m3"] > 0


def test_the_search_step_records_its_choice_and_keeps_a_near_exact_start_near(data):
    """Discovery's ``search`` step on the cabinet's near-exact field: the Kabsch start is already within a
    degree, and the search (here checked on held-out views) must not lead it away."""
    from pd2gs.discovery import pipeline as P

    d = initialised_cabinet(data, "search")
    obj = d.obj
    P.search(d)
    s = d.diag["search"]
    assert s["seconds"] > 0 and set(s["bodies"]) == set(range(1, d.model.num_bodies))
    assert isinstance(s["kept"], bool) and len(s["held_out"]) == 2
    gt = {j.name: (np.array(j.axis, float), j.type) for j in obj.meta.joints}
    found = set()
    for b, jf in model_joints(d.model, d.states, d.start, d.end).items():
        if (d.model.labels() == b).sum() < 50:
            continue  # a stray cluster: selection prunes it
        name = min(gt, key=lambda n: angle_between_deg(jf.axis, gt[n][0]))
        assert jf.type == gt[name][1] and angle_between_deg(jf.axis, gt[name][0]) < 2.0, (b, name, jf)
        found.add(name)
    assert found == set(gt)  # both the door and the drawer carried by a body


def test_the_surface_step_records_a_joint_per_body_that_fits_the_rendered_surfaces_and_leaves_ownership(data):
    """Discovery's ``surface`` step (pd2gs/articulated/surfaces.py) on the cabinet's near-exact field: each
    body gets the joint that best fits the surfaces the field renders in each state (no worse than its
    start there), ownership untouched. Measured, not asserted: on this 64-px fixture it finds the drawer
    (4.9°) but turns the door, a few dozen pixels, into a slide 20° off; the fit and the choice among starts
    by held-out L1 decide whether that start is kept (the lid's hinge test is in
    tests/pd2gs/articulated/test_surfaces.py)."""
    from pd2gs.discovery import pipeline as P

    d = initialised_cabinet(data, "surface")
    labels = d.model.labels().clone()
    P.surface_search(d)
    s = d.diag["surface"]
    assert s["seconds"] > 0 and set(s["bodies"]) == set(range(1, d.model.num_bodies))
    assert all(c["score_after"] <= c["score_before"] for c in s["bodies"].values())
    assert any(c["score_after"] < c["score_before"] for c in s["bodies"].values())
    assert torch.equal(d.model.labels(), labels)
    assert float(d.model.values[d.ref_index].detach().abs().max()) == 0.0


def test_polish_fits_the_chosen_model_on_larger_views(data, monkeypatch):
    """``polish``: more steps of the articulated fit on views of at most ``polish_max_side`` px (here 96, the
    fit's 64), in place, the gauge state's values held; its loss falls."""
    from pd2gs.discovery import pipeline as P

    d = initialised_cabinet(data, "kabsch")
    d.cfg = dataclasses.replace(d.cfg, polish_iters=40, polish_max_side=96)
    sizes = []
    fit = P.fit_articulated
    monkeypatch.setattr(P, "fit_articulated", lambda m, frames, masks, cfg: (sizes.extend(f.size for f in frames),
                                                                          fit(m, frames, masks, cfg))[1])
    before = d.model.values.detach().clone()
    P.polish(d)
    p = d.diag["polish"]
    assert p["max_side"] == 96 and p["seconds"] > 0 and max(max(s) for s in sizes) == 96
    assert max(max(f.size) for f in d.frames) == 64  # the fit's own views are left as they were
    assert p["loss_first_last"][1] < p["loss_first_last"][0] * 1.5  # single-view steps: no blow-up
    assert torch.equal(d.model.values[d.ref_index], before[d.ref_index])
    assert not torch.equal(d.model.values, before)


def test_every_start_is_discovered_and_the_lowest_held_out_l1_kept(data):
    """``starts`` x ``restarts``: one articulated discovery per start and seed; the kept one has the lowest
    held-out L1, and it is the same model that start and seed alone give."""
    from pd2gs.discovery import pipeline as P

    torch.set_num_threads(1)
    obj = rsart.load(data / "cabinet-0000")
    fld, _ = perfect_field(obj.twin, obj.meta, STATES, n=600, jitter=0.002)
    fld = coloured(fld, obj)
    bg = tuple(float(c) for c in obj.states["m0"].views[0].rgb[0, 0] / 255.0)
    quick = dict(fit_max_side=48, background=bg, fit_iters=60, select=False, polish_iters=0)

    def run(**kw):
        d = P.stage1(fld, obj, DiscoveryConfig(**quick, **kw))
        P.articulated_parts(d)
        return d

    many = run(starts="kabsch,search", restarts=2)
    runs = many.diag["starts"]["runs"]
    assert [(r["start"], r["seed"]) for r in runs] == [("kabsch", 0), ("search", 0), ("kabsch", 1), ("search", 1)]
    loss = [r["test_loss"] for r in runs]  # held-out L1 + silhouette term: what selection scores
    assert len(set(loss)) > 1 and many.diag["starts"]["chosen"] == int(np.argmin(loss))
    assert many.diag["test_loss"] == min(loss)
    assert all(r["test_loss"] > r["test_l1"] for r in runs)  # the fixture has masks: the silhouette term counts
    best = runs[int(np.argmin(loss))]
    alone = run(starts=best["start"], seed=best["seed"])
    assert alone.diag["test_loss"] == many.diag["test_loss"] and "starts" not in alone.diag
    assert torch.equal(alone.model.values, many.model.values) and np.array_equal(alone.labels, many.labels)
    assert ("search" in many.diag) == (best["start"] == "search")
    # a search that keeps nothing (as here, on the near-exact field) restores the initial model, so its start
    # shares the Kabsch start's fit instead of repeating it; fitted on its own it gives the very same model
    shared = [r for r in runs if "fit_of" in r]
    for r in shared:
        twin = runs[r["fit_of"]]
        assert r["search_kept"] is False and (twin["start"], twin["seed"]) == ("kabsch", r["seed"])
        assert r["test_l1"] == twin["test_l1"] and r["test_loss"] == twin["test_loss"]
    if shared:
        searched = run(starts="search", seed=shared[0]["seed"])
        kabsch = run(starts="kabsch", seed=shared[0]["seed"])
        assert searched.diag["search"]["kept"] is False
        assert torch.equal(searched.model.values, kabsch.model.values) and np.array_equal(searched.labels, kabsch.labels)
    block = method_block(DiscoveryConfig(starts="kabsch,search", restarts=2))["discovery"]
    assert block["starts"] == "kabsch,search" and block["restarts"] == 2


def test_the_method_block_records_selections_settings():
    """Two submissions that differ only in selection's settings or the seed can be told apart."""
    sel = method_block(DiscoveryConfig(select_iters=600, select_top=2, select_search_bodies=2, select_rounds=9,
                                       seed=1))["discovery"]
    assert (sel["select_iters"], sel["select_top"], sel["select_search_bodies"], sel["select_rounds"],
            sel["seed"], sel["canonical"]) == (600, 2, 2, 9, 1, "widest")


def test_frozen_ownership_fits_the_joints_and_leaves_every_owner_in_place_and_staged_holds_it_half_a_fit(data):
    """``fit_ownership="frozen"``: the fit moves the joints but no Gaussian changes body (the
    free fit, from the same start, does move some); the submission's method block says which was run."""
    from pd2gs.discovery import pipeline as P

    moved = {}
    for mode in ("free", "frozen"):
        d = initialised_cabinet(data, "kabsch")
        d.cfg = dataclasses.replace(d.cfg, fit_ownership=mode, fit_iters=120)
        labels0, values0 = d.model.labels().clone(), d.model.values.detach().clone()
        P.fit(d)
        assert not torch.equal(d.model.values.detach(), values0)
        moved[mode] = int((d.model.labels() != labels0).sum())
        assert method_block(d.cfg)["discovery"]["fit_ownership"] == mode
    assert moved["frozen"] == 0 and moved["free"] > 0, moved
    d.cfg = dataclasses.replace(d.cfg, fit_ownership="staged")  # held for the first half of every fit, then free
    staged, free = P.fit_config(d, 120), FitConfig()
    assert (staged.ownership_warmup, staged.lr_ownership, staged.reassign_every) == (60, free.lr_ownership,
                                                                                      free.reassign_every)
    assert method_block(d.cfg)["discovery"]["fit_ownership"] == "staged"


@pytest.mark.parametrize("starts", ["", "kabsch,kabsch", "grid"])
def test_bad_starts_are_refused_by_name(starts):
    from pd2gs.config_cli import ConfigError

    with pytest.raises(ConfigError, match="starts"):
        DiscoveryConfig(starts=starts)


def test_each_canonical_state_is_discovered_and_the_lowest_held_out_loss_kept(data):
    """``canonical="widest,start"``: the cabinet's widest state (m3) and its start (m0) each give a discovery;
    the kept one has the lower held-out loss, is canonical at its own state, and is the model that canonical
    alone gives."""
    from pd2gs.discovery import pipeline as P

    torch.set_num_threads(1)
    obj = rsart.load(data / "cabinet-0000")
    fld, _ = perfect_field(obj.twin, obj.meta, STATES, n=600, jitter=0.002)
    fld = coloured(fld, obj)
    bg = tuple(float(c) for c in obj.states["m0"].views[0].rgb[0, 0] / 255.0)
    quick = dict(fit_max_side=48, background=bg, fit_iters=60, select=False, polish_iters=0, starts="kabsch")

    def run(**kw):
        d = P.stage1(fld, obj, DiscoveryConfig(**quick, **kw))
        P.articulated_parts(d)
        return d

    both = run(canonical="widest,start")
    runs = both.diag["starts"]["runs"]
    assert [(r["start"], r["canonical"]) for r in runs] == [("kabsch", "m3"), ("kabsch", "m0")]
    loss = [r["test_loss"] for r in runs]
    assert loss[0] != loss[1] and both.diag["starts"]["chosen"] == int(np.argmin(loss))
    kept = runs[int(np.argmin(loss))]["canonical"]
    assert both.diag["canonical"]["state"] == kept and both.states[both.ref_index] == kept
    alone = run(canonical="widest" if kept == "m3" else "start")
    assert "starts" not in alone.diag and alone.diag["test_loss"] == both.diag["test_loss"]
    assert torch.equal(alone.model.values, both.model.values) and np.array_equal(alone.labels, both.labels)
    # rules naming the same state are discovered once
    d = P.stage1(fld, obj, DiscoveryConfig(**quick, canonical="start,widest"))
    assert P.canonical_states(d) == ["m0", "m3"]
    one = P.stage1(fld, obj, DiscoveryConfig(**quick, canonical="start"))
    assert P.canonical_states(one) == ["m0"]


@pytest.mark.parametrize("canonical", ["", "start,start", "end", "widest;start"])
def test_bad_canonical_rules_are_refused_by_name(canonical):
    from pd2gs.config_cli import ConfigError

    with pytest.raises(ConfigError, match="canonical"):
        DiscoveryConfig(canonical=canonical)


def test_starts_fitted_side_by_side_give_the_models_of_one_after_another(data):
    """With two threads the starts are fitted in two child processes of one thread each
    (pd2gs/discovery/side_by_side.py); each gives the very model it gives fitted in this process with one
    thread, and the choice among them is the same."""
    from pd2gs.discovery import pipeline as P

    obj = rsart.load(data / "cabinet-0000")
    fld, _ = perfect_field(obj.twin, obj.meta, STATES, n=600, jitter=0.002)
    fld = coloured(fld, obj)
    bg = tuple(float(c) for c in obj.states["m0"].views[0].rgb[0, 0] / 255.0)
    cfg = DiscoveryConfig(fit_max_side=48, background=bg, fit_iters=60, select=False, polish_iters=0,
                          starts="kabsch,surface")  # (a search that keeps nothing shares the Kabsch fit)

    def run(threads):
        old = torch.get_num_threads()
        torch.set_num_threads(threads)
        try:
            d = P.stage1(fld, obj, cfg)
            P.articulated_parts(d)
        finally:
            torch.set_num_threads(old)
        return d

    alone, side = run(1), run(2)
    assert [r["test_loss"] for r in side.diag["starts"]["runs"]] == [r["test_loss"] for r in alone.diag["starts"]["runs"]]
    assert side.diag["starts"]["chosen"] == alone.diag["starts"]["chosen"]
    assert torch.equal(side.model.values, alone.model.values) and np.array_equal(side.labels, alone.labels)
    assert side.obj is obj


def test_a_failing_child_hands_the_step_back(caplog):
    from pd2gs.discovery.pipeline import fit_and_select
    from pd2gs.discovery.side_by_side import run_side_by_side

    assert run_side_by_side(fit_and_select, [{"not": "a run"}, {"not": "a run"}], 1, 2) is None
    assert "fit_and_select side by side failed" in caplog.text and "AttributeError" in caplog.text
