"""Means that giving up cannot game: a submission that nulls one object keeps the paper-convention mean
(failure left out, marked ``*``) and gets a completion rate and a penalised mean in which the failure counts
as the metric's worst value. Every expected number below is worked out by hand from the perturbation."""
from __future__ import annotations

import json

import numpy as np
import pytest

from rsart.evaluation import (EvalConfig, load_ground_truth, make_gt_submission, parse_perturbation,
                              read_submission, score_submission)
from rsart.evaluation.report import build_scores, penalty_cap, plot_bars, summary_markdown, summary_plot
from rsart.format import read_meta
from rsart.metrics.chamfer import ChamferConfig
from rsart.twin_io import read_twin

FAST = EvalConfig(chamfer=ChamferConfig(n_samples=2000, seeds=(0,)))
pytestmark = pytest.mark.core  # runs on the core install alone (.ci/core)


def score(path, dataset):
    gt = load_ground_truth(dataset)
    sub, problems = read_submission(path, gt)
    assert problems == [], problems
    res, problems = score_submission(sub, gt, FAST, workers=1)
    assert problems == []
    return res


@pytest.fixture
def nulled(dataset, tmp_path):
    """axis=5deg perturbed GT submission with cabinet-0001 (one of the two storage objects) null -> scores."""
    out = tmp_path / "pert"
    make_gt_submission(load_ground_truth(dataset), out, "start,end", parse_perturbation("axis=5deg,seed=0"))
    f = out / "submission.json"
    d = json.loads(f.read_text())
    d["results"]["cabinet-0001"] = None
    f.write_text(json.dumps(d))
    res = score(f, dataset)
    return build_scores(res, config=FAST.to_dict(), config_hash=FAST.hash(), toolkit_version="t",
                        dataset={"name": "tiny"}, submission={"method": {"name": "m"}})


def _diag(folder) -> float:
    meta = read_meta(folder)
    twin = read_twin(folder, meta, visuals=False)
    b = np.concatenate([twin.bounds(meta.state(meta.eval_states[k]).values) for k in ("start", "end")])
    return float(np.linalg.norm(b.max(0) - b.min(0)))


def test_null_object_enters_the_penalised_mean_at_the_worst_value(dataset, nulled):
    agg = nulled["aggregate"]
    st, lamp = agg["categories"]["storage"]["metrics"], agg["categories"]["lamp"]["metrics"]
    mc = agg["overall"]["mean_of_categories"]
    # Axis Ang: every scored part is tilted by exactly 5°; the null cabinet counts 90°.
    assert st["axis_ang"]["mean"] == pytest.approx(5.0, abs=1e-6)               # paper convention: 5*
    assert st["axis_ang"]["n_failed"] == 1
    assert st["axis_ang"]["penalised_mean"] == pytest.approx((5 + 90) / 2, abs=1e-6)   # 47.5
    assert lamp["axis_ang"]["penalised_mean"] == pytest.approx(5.0, abs=1e-6)
    assert mc["axis_ang"]["mean"] == pytest.approx(5.0, abs=1e-6)
    assert mc["axis_ang"]["penalised_mean"] == pytest.approx((47.5 + 5) / 2, abs=1e-6)  # 26.25
    # completion: storage 1 of 2 objects, lamp 1 of 1; Mean column = mean over categories
    assert st["axis_ang"]["completion"] == 0.5 and lamp["axis_ang"]["completion"] == 1.0
    assert mc["axis_ang"]["completion"] == 0.75
    assert agg["overall"]["completion"] == pytest.approx(2 / 3)
    # accuracies: the failure counts 0 %
    assert st["count_acc"]["mean"] == 1.0 and st["count_acc"]["penalised_mean"] == 0.5
    assert mc["count_acc"]["penalised_mean"] == 0.75
    # revolute Part Motion: the perturbation tilts the axis only, the null cabinet counts 180°
    pm = st["part_motion_rev"]
    assert pm["penalised_mean"] == pytest.approx((pm["mean"] + 180) / 2, abs=1e-9)
    # size-derived caps: CD 2000·d², Axis Pos 10·d, prismatic Part Motion d (d = bounding-box diagonal)
    d = _diag(dataset / "cabinet-0001")
    obj = nulled["objects"]["cabinet-0000"]["metrics"]
    assert st["cd_s"]["penalised_mean"] == pytest.approx((obj["cd_s"] + 2000 * d * d) / 2, rel=1e-9)
    assert st["axis_pos"]["penalised_mean"] == pytest.approx((obj["axis_pos"] + 10 * d) / 2, rel=1e-9)
    assert st["part_motion_pri"]["penalised_mean"] == pytest.approx((obj["part_motion_pri"] + d) / 2, rel=1e-9)
    assert nulled["objects"]["cabinet-0001"]["bbox_diag"] == pytest.approx(d)


def test_skipping_an_object_never_beats_trying_it(dataset, nulled, tmp_path):
    """The same perturbed submission without the null: its penalised mean is better than with it, while the
    paper-convention mean cannot tell them apart."""
    out = tmp_path / "full"
    make_gt_submission(load_ground_truth(dataset), out, "start,end", parse_perturbation("axis=5deg,seed=0"))
    full = build_scores(score(out / "submission.json", dataset), config=FAST.to_dict(), config_hash=FAST.hash(),
                        toolkit_version="t", dataset={"name": "tiny"}, submission={"method": {"name": "m"}})
    a, b = full["aggregate"]["overall"]["mean_of_categories"], nulled["aggregate"]["overall"]["mean_of_categories"]
    assert a["axis_ang"]["mean"] == pytest.approx(b["axis_ang"]["mean"], abs=1e-6)
    assert a["axis_ang"]["penalised_mean"] == pytest.approx(5.0, abs=1e-6)
    assert b["axis_ang"]["penalised_mean"] > 5.0 + 1e-3
    assert a["axis_ang"]["completion"] == 1.0
    for k in ("cd_s", "cd_w", "axis_pos", "type_acc", "count_acc"):
        worse = b[k]["penalised_mean"] < a[k]["penalised_mean"] if k.endswith("acc") else \
            b[k]["penalised_mean"] > a[k]["penalised_mean"]
        assert worse, k


def test_scored_values_are_clipped_to_the_cap():
    assert penalty_cap("axis_ang", None) == 90.0
    assert penalty_cap("type_acc", None) == 0.0
    assert penalty_cap("cd_w_start", 0.5) == pytest.approx(500.0)
    assert penalty_cap("cd_s", None) is None  # old scores without bbox_diag: no penalised value, never a guess
    from rsart.evaluation.report import penalised_object_value

    res = {"metrics": {"cd_s": 1e9}, "failures": {}, "parts": [], "bbox_diag": 1.0}
    assert penalised_object_value(res, "cd_s") == 2000.0  # a wild attempt is never worse than giving up


def test_summary_shows_both_means_and_completion_and_no_units_placeholder(nulled):
    md = summary_markdown(nulled)
    head = next(line for line in md.splitlines() if line.startswith("| Metric"))
    assert head.rstrip(" |").endswith("Mean | Penalised mean | Completion")
    row = [c.strip() for c in next(line for line in md.splitlines() if line.startswith("| Axis Ang")).strip("|").split("|")]
    # lamp, storage, Mean, Penalised mean, Completion
    assert row[1:] == ["5.000", "5.000*", "5.000*", "26.250", "75 %"]
    assert "Units: units" not in md


def test_summary_plot_draws_no_zero_bar_for_missing_values(nulled):
    bars = dict((lbl, (v, note)) for lbl, v, note in plot_bars(nulled, "axis_pos"))
    assert bars["lamp"][0] is not None and bars["Penalised"][0] is not None
    # image metrics are not applicable here: no bar, noted n/a
    assert all(v is None and note == "n/a" for _l, v, note in plot_bars(nulled, "psnr"))
    png = summary_plot(nulled)
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_null_object_counts_zero_in_image_metrics_the_submission_scored(dataset, tmp_path):
    """Renders for cabinet-0000 only, cabinet-0001 null: storage PSNR penalised = (PSNR + 0) / 2; the lamp
    (scored, but no renders) stays not applicable."""
    import shutil

    from rsart.io import write_png_rgb

    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
    write_png_rgb(dataset / "cabinet-0000" / "states" / "m0" / "rgb" / "0000.png", rgb)
    out = tmp_path / "img"
    make_gt_submission(load_ground_truth(dataset), out)
    write_png_rgb(out / "r.png", np.clip(rgb.astype(int) + 10, 0, 255).astype(np.uint8))
    f = out / "submission.json"
    d = json.loads(f.read_text())
    d["results"]["cabinet-0000"]["renders"] = {"m0": {"0000": "r.png"}}
    d["results"]["cabinet-0001"] = None
    f.write_text(json.dumps(d))
    scores = build_scores(score(f, dataset), config=FAST.to_dict(), config_hash=FAST.hash(), toolkit_version="t",
                          dataset={"name": "tiny"}, submission={"method": {"name": "m"}})
    st = scores["aggregate"]["categories"]["storage"]["metrics"]["psnr"]
    psnr = scores["objects"]["cabinet-0000"]["metrics"]["psnr"]
    assert st["mean"] == pytest.approx(psnr) and st["n_failed"] == 0          # paper convention: the null drops out
    assert st["penalised_mean"] == pytest.approx(psnr / 2) and st["completion"] == 0.5
    lamp = scores["aggregate"]["categories"]["lamp"]["metrics"]["psnr"]
    assert lamp["n_applicable"] == 0 and lamp["penalised_mean"] is None
    shutil.rmtree(out)
