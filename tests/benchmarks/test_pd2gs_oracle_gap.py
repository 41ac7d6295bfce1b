"""benchmarks/pd2gs_oracle_gap.py's truth: the model it builds from a twin moves every part as the twin does.

The diagnostic compares discovery's fit with a fit from the true ownership, joints and tree; a wrong frame
for a chain's child joint or a sign slip in the values would make "the truth" a wrong model and the
comparison meaningless. Real procedural twins (a stand: a hinge carried by a hinge; a drawer: slides).
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from tests.benchmarks.bench_helpers import on_path


@pytest.fixture(scope="module")
def bench():
    with on_path("pd2gs_oracle_gap.py") as mod:
        yield mod


def _values(twin, fracs, ref_frac):
    """Joint values at fractions of each joint's range (a ramp of states), and the reference state's index."""
    lim = {j.name: j.limits or (0.0, np.pi / 2) for j in twin.joints}
    states = [{n: float(lo + f * (hi - lo)) for n, (lo, hi) in lim.items()} for f in fracs]
    return states, fracs.index(ref_frac)


@pytest.mark.parametrize("category,seed,ref_frac", [("stand", 0, 1.0), ("stand", 0, 0.4), ("drawer", 0, 0.0)])
def test_the_true_model_poses_every_part_as_the_twin(bench, category, seed, ref_frac):
    from pd2gs.articulated.model import canonical_gaussians
    from rsart.sources.procedural.registry import generate

    twin = generate(category, seed).twin
    fracs = [0.0, 0.4, 0.7, 1.0]
    svals, ref = _values(twin, fracs, ref_frac)
    meshes = twin.posed_meshes(svals[ref])
    pts = np.concatenate([m.sample(300, seed=p) for p, m in enumerate(meshes)])
    part = np.repeat(np.arange(len(meshes)), 300)
    assert (bench.true_labels(twin, svals[ref], pts) == part).mean() > 0.97  # nearest surface: its own part

    truth = bench.true_joints(twin, svals, ref)
    parts = sorted(truth)
    parent = [-1] + [next(j.parent for j in twin.joints if j.child == p) for p in parts]
    n = len(pts)
    g = canonical_gaussians(pts, np.tile([1.0, 0, 0, 0], (n, 1)), np.full((n, 3), 1e-3), np.full((n, 3), 0.5),
                            np.full(n, 0.9), dtype=torch.float64)
    model = bench.build_model(g, part, parent, [truth[p] for p in parts])
    model.hard = True
    T_ref = twin.pose(svals[ref])
    for s, vals in enumerate(svals):
        T = twin.pose(vals)
        want = np.concatenate([(T[p] @ np.linalg.inv(T_ref[p]) @ np.c_[pts[part == p], np.ones((part == p).sum())].T).T[:, :3]
                               for p in range(len(meshes))])
        got = model.pose(s)[0].detach().numpy()
        assert np.abs(got - want).max() < 1e-6, (category, s)  # float32 means: 1 µm
    if category == "stand":  # the holder hangs on the arm: a chain, not two flat joints
        assert parent[2] == 1 and abs(truth[2][3]).max() > 0.1


def test_body_errors_match_bodies_to_parts_and_flip_signs(bench):
    from pd2gs.articulated.model import canonical_gaussians

    n = 40
    g = canonical_gaussians(np.random.default_rng(0).normal(size=(n, 3)), np.tile([1.0, 0, 0, 0], (n, 1)),
                            np.full((n, 3), 1e-2), np.full((n, 3), 0.5), np.full(n, 0.9))
    vals = np.array([0.0, 0.5, 1.0])
    truth = {1: ("revolute", np.array([0.0, 0, 1]), np.zeros(3), vals),
             2: ("prismatic", np.array([1.0, 0, 0]), np.zeros(3), vals / 10)}
    own = np.r_[np.zeros(10), np.ones(20), np.full(10, 2)].astype(int)
    # body 1: part 1's joint with the axis flipped and the values negated (the same motion), part 2's Gaussians
    # hold body 2 but as a hinge
    # (its pivot 3 cm off the true line and 0.5 m along it)
    m = bench.build_model(g, own, [-1, 0, 0], [("revolute", -truth[1][1], np.array([0.0, 0.03, 0.5]), -vals),
                                               ("revolute", np.array([0.0, 1, 0]), np.zeros(3), vals)])
    gt = own.copy()
    gt[10:12] = 2  # two of body 1's Gaussians belong to part 2
    rows = bench.body_errors(m, gt, truth)
    assert rows[0]["part"] == 1 and rows[0]["purity"] == pytest.approx(0.9)
    assert rows[0]["axis_err_deg"] == pytest.approx(0.0, abs=1e-4) and rows[0]["value_err"] == pytest.approx(0.0, abs=1e-6)
    assert rows[0]["line_err_cm"] == pytest.approx(3.0, abs=1e-4)  # along the line does not count
    assert rows[1]["part"] == 2 and rows[1]["axis_err_deg"] == pytest.approx(90.0, abs=1e-4)
    assert "value_err" not in rows[1] and "line_err_cm" not in rows[1]  # a hinge against a slide


def test_report_names_a_search_that_kept_nothing_and_the_line_errors(bench):
    body = {"body": 1, "part": 1, "type": "revolute", "purity": 0.5, "axis_err_deg": 1.0, "value_err": 2.0,
            "line_err_cm": 3.25}
    arms = ["kabsch", "search"]
    rec = {"object_id": "lid", "canonical": "m3", "true_sizes": [5, 3], "search_kept": False,
           "arms": {a: {"held_out": 0.01 + i / 1000, "held_out_start": 0.02, "bodies": [body],
                        "bodies_start": [dict(body, line_err_cm=9.0)]} for i, a in enumerate(arms)}}
    md = bench.report([rec], arms, 600, "# t")
    assert "| lid | m3 | **0.01000** (0.02000) | 0.01100 (0.02000) |" in md
    assert "kabsch, before the fit: b1→p1 rev 50 %, axis 1.0°, value ≤ 2.0°, line 9.0 cm" in md
    assert "search (kept nothing: the kabsch start): b1→p1" in md and "line 3.2 cm" in md
