"""Scoring: ground truth scores 0 / the Chamfer floor, perturbations score their analytic errors,
matching, part-count and type mismatches, failures, aggregation, determinism across workers."""
from __future__ import annotations

import copy
import json
import math

import pytest

from rsart.evaluation import (EvalConfig, load_ground_truth, make_gt_submission, parse_perturbation,
                              read_submission, score_submission)
from rsart.metrics.chamfer import ChamferConfig
from rsart.evaluation.report import aggregate, build_scores, summary_markdown

JOINT_KEYS = ("axis_ang", "axis_pos", "part_motion")
FAST = EvalConfig(chamfer=ChamferConfig(n_samples=2000, seeds=(0,)))  # tests not about Chamfer noise


def score(path, dataset, workers=1, cfg=FAST):
    gt = load_ground_truth(dataset)
    sub, problems = read_submission(path, gt)
    assert problems == [], problems
    res, problems = score_submission(sub, gt, cfg, workers=workers)
    assert problems == []
    return res


def test_ground_truth_scores_zero_joint_error_and_the_chamfer_floor(dataset, gt_submission_dir):
    res = score(gt_submission_dir / "submission.json", dataset, cfg=EvalConfig())
    assert set(res) == {"cabinet-0000", "cabinet-0001", "lamp-0000"}
    for r in res.values():
        assert r["status"] == "scored" and r["failures"] == {}
        assert r["metrics"]["count_acc"] == 1.0 and r["metrics"]["type_acc"] == 1.0
        for p in r["parts"]:
            assert p["pred"] == p["name"]
            for k in JOINT_KEYS:
                if k in p["metrics"]:
                    assert abs(p["metrics"][k]) < 1e-9, (r["object_id"], p["name"], k, p["metrics"][k])
        # Chamfer: only sampling noise, bounded by the analytic floor 2000·A/(π·N) (+15%)
        for sid in r["chamfer_states"]:
            fl = r["chamfer_floor"][sid]
            assert 0 < r["chamfer_by_state"][f"cd_s@{sid}"] < 1.15 * fl["static"]
            assert 0 < r["chamfer_by_state"][f"cd_w@{sid}"] < 1.15 * fl["whole"]
    # the cabinet has one revolute and one prismatic part: prismatic Axis Pos is excluded, not 0
    cab = res["cabinet-0000"]
    assert "axis_pos" in cab["parts"][1]["not_applicable"] and "axis_pos" not in cab["parts"][1]["metrics"]


@pytest.mark.parametrize("spec,expect", [
    ("axis=5deg", {"axis_ang": 5.0, "axis_pos": 0.0}),
    ("pivot=0.02", {"axis_ang": 0.0, "axis_pos": 0.2, "part_motion": 0.0}),
    ("motion=3deg,travel=0.01", {"axis_ang": 0.0, "axis_pos": 0.0}),
    ("axis=5deg,pivot=0.02,motion=3deg,seed=7", {"axis_ang": 5.0, "axis_pos": 0.2}),
])
def test_perturbed_ground_truth_scores_the_analytic_error(dataset, tmp_path, spec, expect):
    gt = load_ground_truth(dataset)
    path = make_gt_submission(gt, tmp_path / "p", perturbation=parse_perturbation(spec))
    expected = json.loads((tmp_path / "p" / "expected_errors.json").read_text())["objects"]
    res = score(path, dataset)
    for oid, r in res.items():
        for p in r["parts"]:
            exp = expected[oid][p["name"]]
            for k, v in expect.items():
                if k == "axis_pos" and p["type"] == "prismatic":
                    assert k not in p["metrics"]
                    continue
                assert p["metrics"][k] == pytest.approx(v, abs=1e-6), (oid, p["name"], k)
            for k in JOINT_KEYS:  # closed forms written by the generator, independent of rsart.metrics
                if exp[k] is not None:
                    assert p["metrics"][k] == pytest.approx(exp[k], abs=1e-6), (oid, p["name"], k)
    if spec.startswith("motion"):
        lid = res["cabinet-0000"]["parts"][0]
        drawer = res["cabinet-0000"]["parts"][1]
        assert lid["metrics"]["part_motion"] == pytest.approx(3.0, abs=1e-6)
        assert drawer["metrics"]["part_motion"] == pytest.approx(0.01, abs=1e-9)


def test_shuffled_part_order_and_names_are_matched(dataset, sub_copy):
    d, data, save = sub_copy
    parts = data["results"]["cabinet-0000"]["parts"]
    data["results"]["cabinet-0000"]["parts"] = {"static": parts["static"], "B": parts["drawer"], "A": parts["lid"]}
    res = score(save(), dataset)["cabinet-0000"]
    assert [p["pred"] for p in res["parts"]] == ["A", "B"]
    assert res["metrics"]["axis_ang"] == 0.0 and res["metrics"]["count_acc"] == 1.0


def test_fewer_predicted_parts_fail_the_unmatched_part(dataset, sub_copy):
    d, data, save = sub_copy
    del data["results"]["cabinet-0000"]["parts"]["lid"]
    res = score(save(), dataset)
    r = res["cabinet-0000"]
    lid, drawer = r["parts"]
    assert lid["pred"] is None and set(lid["failures"]) >= {"axis_ang", "axis_pos", "part_motion", "cd_m"}
    assert drawer["metrics"]["part_motion"] == 0.0
    assert r["metrics"]["count_acc"] == 0.0
    assert r["part_failures"]["axis_ang"] == 1
    assert r["metrics"]["axis_ang"] == 0.0  # mean over the scored part only
    assert "axis_pos" in r["failures"]      # the only revolute part failed
    # whole = union of predicted parts: the missing lid (lying flat on the base) raises CD-w
    assert r["metrics"]["cd_w"] > 1.2 * res["cabinet-0001"]["metrics"]["cd_w"]
    agg = aggregate(res)["categories"]["storage"]["metrics"]
    assert agg["axis_ang"]["n_failed"] == 1 and agg["axis_ang"]["n"] == 2
    assert agg["count_acc"]["mean"] == 0.5


def test_more_predicted_parts_lower_the_count_accuracy(dataset, sub_copy):
    d, data, save = sub_copy
    parts = data["results"]["cabinet-0000"]["parts"]
    extra = copy.deepcopy(parts["lid"])
    extra["joint"]["axis"] = [0.0, 0.0, 1.0]
    extra["joint"]["origin"] = [1.0, 1.0, 0.0]
    data["results"]["cabinet-0000"]["parts"] = {"static": parts["static"], "extra": extra, **{k: v for k, v in parts.items() if k != "static"}}
    r = score(save(), dataset)["cabinet-0000"]
    assert r["unmatched_pred"] == ["extra"]
    assert [p["pred"] for p in r["parts"]] == ["lid", "drawer"]
    assert r["metrics"]["count_acc"] == 0.0 and r["metrics"]["axis_ang"] == 0.0


def test_type_mismatch(dataset, sub_copy):
    d, data, save = sub_copy
    data["results"]["cabinet-0000"]["parts"]["drawer"]["joint"]["type"] = "revolute"
    r = score(save(), dataset)["cabinet-0000"]
    assert r["parts"][1]["pred_type"] == "revolute" and r["parts"][1]["metrics"]["type_acc"] == 0.0
    assert r["metrics"]["type_acc"] == 0.5
    assert r["parts"][1]["metrics"]["part_motion"] == 0.0  # read as prismatic (the true type)


def test_null_object_is_a_counted_failure_never_a_number(dataset, sub_copy):
    d, data, save = sub_copy
    data["results"]["lamp-0000"] = None
    res = score(save(), dataset)
    lamp = res["lamp-0000"]
    assert lamp["status"] == "failed" and lamp["metrics"] == {}
    assert "cd_s" in lamp["failures"] and all("axis_ang" in p["failures"] for p in lamp["parts"])
    scores = build_scores(res, config=EvalConfig().to_dict(), config_hash=EvalConfig().hash(), toolkit_version="t",
                          dataset={"name": "tiny"}, submission={"method": {"name": "m"}})
    text = json.dumps(scores, allow_nan=False)  # raises on NaN/inf
    assert "-1000" not in text
    agg = scores["aggregate"]
    assert agg["overall"]["n_failed_objects"] == 1
    assert agg["categories"]["lamp"]["metrics"]["axis_ang"] == {"mean": None, "n": 0, "n_failed": 1, "n_applicable": 1,
                                                                "completion": 0.0, "penalised_mean": 90.0}
    # the Mean column averages the categories that scored: storage only
    assert agg["overall"]["mean_of_categories"]["axis_ang"]["mean"] == agg["categories"]["storage"]["metrics"]["axis_ang"]["mean"]
    md = summary_markdown(scores)
    row = next(line for line in md.splitlines() if line.startswith("| Axis Ang"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[1] == "*"                     # lamp column (categories sorted: lamp, storage)
    assert cells[2] == "0.000"                 # storage
    assert cells[3] == "0.000*"                # Mean carries the failure mark
    assert cells[4] == "45.000"                # penalised: (lamp 90 + storage 0) / 2
    assert cells[5] == "50 %"                  # completion: (lamp 0 + storage 1) / 2
    assert "lamp-0000" in md.split("## Failures")[1]


def test_workers_1_and_2_give_identical_scores(dataset, gt_submission_dir):
    a = score(gt_submission_dir / "submission.json", dataset, workers=1)
    b = score(gt_submission_dir / "submission.json", dataset, workers=2)
    assert json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def test_states_all_scores_every_state(dataset, gt_submission_dir, tmp_path):
    gt = load_ground_truth(dataset, split="lamps")
    path = make_gt_submission(gt, tmp_path / "all", states="all")
    sub, problems = read_submission(path, gt)
    assert problems == []
    res, _ = score_submission(sub, gt, EvalConfig(chamfer=FAST.chamfer, states="all"), workers=1)
    r = res["lamp-0000"]
    assert len(r["chamfer_states"]) == len(gt.meta("lamp-0000").states)
    assert len([k for k in r["chamfer_by_state"] if k.startswith("cd_s@")]) == len(r["chamfer_states"])
    # a start/end-only submission scored on all states fails (counted) in the missing ones
    sub2, _ = read_submission(gt_submission_dir / "submission.json", load_ground_truth(dataset))
    res2, _ = score_submission(sub2, gt, EvalConfig(chamfer=FAST.chamfer, states="all"), workers=1)
    assert "cd_s" in res2["lamp-0000"]["failures"] and "cd_s_start" in res2["lamp-0000"]["metrics"]


def test_chained_joint_is_scored_in_the_start_frame(dataset, tmp_path):
    """The lamp's elbow rides on the shoulder: its GT axis at the start state is the rest axis moved by the
    shoulder's start value; the GT submission (written in that frame) must score 0."""
    gt = load_ground_truth(dataset, split="lamps")
    meta = gt.meta("lamp-0000")
    start = meta.state(meta.eval_states["start"]).values
    assert start["shoulder"] != 0.0  # otherwise the test would not distinguish the frames
    path = make_gt_submission(gt, tmp_path / "s")
    sub, _ = read_submission(path, gt)
    res, _ = score_submission(sub, gt, FAST, workers=1)
    elbow = res["lamp-0000"]["parts"][1]
    assert elbow["metrics"]["axis_pos"] < 1e-9 and elbow["metrics"]["axis_ang"] < 1e-9


def test_renders_and_masks_are_scored_against_the_dataset_images(dataset, sub_copy):
    import numpy as np

    from rsart.io import write_mask_png, write_png_rgb

    d, data, save = sub_copy
    obj = dataset / "cabinet-0000" / "states" / "m0"
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
    mask = np.zeros((24, 32), np.uint8)
    mask[:, :10], mask[:, 10:20], mask[:, 20:] = 1, 2, 3  # base, lid, drawer
    write_png_rgb(obj / "rgb" / "0000.png", rgb)
    write_mask_png(obj / "mask" / "0000.png", mask)
    noisy = np.clip(rgb.astype(int) + 10, 0, 255).astype(np.uint8)
    write_png_rgb(d / "r.png", noisy)
    # the submission lists parts as static, drawer, lid -> labels 1, 2, 3 (JSON order, static first)
    parts = data["results"]["cabinet-0000"]["parts"]
    data["results"]["cabinet-0000"]["parts"] = {"static": parts["static"], "drawer": parts["drawer"], "lid": parts["lid"]}
    pm = np.where(mask == 2, 3, np.where(mask == 3, 2, mask)).astype(np.uint8)
    pm[0, :10] = 0  # 10 background pixels wrong in the base
    write_mask_png(d / "m.png", pm)
    data["results"]["cabinet-0000"]["renders"] = {"m0": {"0000": "r.png"}}
    data["results"]["cabinet-0000"]["masks"] = {"m0": {"0000": "m.png"}}
    res = score(save(), dataset)
    r = res["cabinet-0000"]
    mse = np.mean((noisy / 255.0 - rgb / 255.0) ** 2)
    assert r["metrics"]["psnr"] == pytest.approx(10 * math.log10(1 / mse))
    assert 0 < r["metrics"]["ssim"] < 1
    assert r["metrics"]["mask_acc"] == pytest.approx(1 - 10 / (24 * 32))
    assert r["metrics"]["mask_iou"] == pytest.approx((230 / 240 + 1 + 1) / 3)
    assert "psnr" in res["cabinet-0001"]["not_applicable"]


def test_typed_records_give_the_json_dicts(dataset, sub_copy):
    """score_records returns ObjectScore/PartScore records; their to_dict() is what score_submission returns."""
    from rsart.evaluation.score import ObjectScore, PartScore, score_records

    _, d, save = sub_copy
    d["results"]["lamp-0000"] = None
    path = save()
    gt = load_ground_truth(dataset)
    sub, _ = read_submission(path, gt)
    recs, _ = score_records(sub, gt, FAST, workers=1)
    dicts, _ = score_submission(sub, gt, FAST, workers=1)
    assert all(isinstance(r, ObjectScore) and all(isinstance(p, PartScore) for p in r.parts) for r in recs.values())
    assert {k: r.to_dict() for k, r in recs.items()} == dicts
    lamp = recs["lamp-0000"]
    assert lamp.status == "failed" and lamp.reason and not lamp.metrics and lamp.failures
