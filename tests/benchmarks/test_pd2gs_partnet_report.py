"""The pure parts of benchmarks/pd2gs_partnet.py: target arithmetic, null/missing objects, the report, bad input."""
from __future__ import annotations

import pytest

from tests.benchmarks.bench_helpers import on_path


@pytest.fixture(scope="module")
def bench():
    with on_path("pd2gs_partnet.py") as mod:  # it imports its sibling pd2gs_suite
        yield mod


def _part(name, ang, typ="revolute", pred="p1"):
    m = {} if ang is None else {"axis_ang": ang, "axis_pos": 0.01, "part_motion": 0.2, "cd_m": 1.0}
    return {"name": name, "type": typ, "pred": pred if ang is not None else None,
            "pred_type": typ if ang is not None else None, "metrics": m}


def _scores():
    return {"objects": [
        {"object_id": "pm-148", "category": "Faucet", "status": "scored", "n_true_movable": 1, "n_pred_movable": 1,
         "metrics": {"count_acc": 1.0, "cd_s": 1.0, "cd_w": 0.5, "axis_ang": 0.5}, "parts": [_part("switch_0", 0.5)]},
        {"object_id": "pm-100676", "category": "Box", "status": "scored", "n_true_movable": 4, "n_pred_movable": 3,
         "metrics": {"count_acc": 0.0, "cd_s": 9.0, "cd_w": 7.0},
         "parts": [_part("lid_0", 1.0), _part("lid_1", 2.0), _part("lid_2", 3.0), _part("lid_3", None)]},
        {"object_id": "pm-101326", "category": "Eyeglasses", "status": "failed", "n_true_movable": 2,
         "reason": "no result (null in the submission)", "metrics": {},
         "parts": [_part("leg_0", None), _part("leg_1", None)]},
    ]}


def test_targets_count_nulls_and_missing_objects(bench):
    ids = ["148", "100676", "101326", "3763"]
    recs = bench.object_records(_scores(), ids, {"3763": "conversion failed: boom"}, {})
    assert [r["status"] for r in recs] == ["scored", "scored", "failed", "missing"]
    s = bench.summary(recs)
    assert s["count_right"] == 1 and s["n_null"] == 2
    assert s["n_parts_scored"] == 4 and s["n_parts_missed"] == 3 and s["objects_unknown"] == 1
    assert s["axis_ang_mean_scored"] == pytest.approx(6.5 / 4)
    assert s["axis_ang_mean_penalised"] == pytest.approx((6.5 + 3 * 90) / 7)
    assert s["axis_ang_met"] is False  # an unconverted object's parts are unknown: never "met"
    assert s["cd_w_vs_paper"] == {"100676": {"ours": 7.0, "paper": 8.03, "met": True}} and s["cd_w_met"] is True


def test_axis_target_met_and_cd_w_above_the_paper(bench):
    sc = _scores()
    sc["objects"] = sc["objects"][:2]
    sc["objects"][1]["parts"][3] = _part("lid_3", 1.0)
    sc["objects"][1]["metrics"]["cd_w"] = 9.0
    s = bench.summary(bench.object_records(sc, ["148", "100676"], {}, {}))
    assert s["axis_ang_mean_penalised"] == pytest.approx(7.5 / 5) and s["axis_ang_met"] is True
    assert s["cd_w_met"] is False


def test_report_renders_every_object_and_the_paper_numbers(bench):
    ids = ["148", "100676", "101326", "3763"]
    recs = bench.object_records(_scores(), ids, {"3763": "conversion failed: boom"}, {"3763": 1})
    s = bench.summary(recs)
    timing = {"pm-101326": {"reason": "KeyError: 'size'"}, "pm-148": {"train_s": 10.0, "discover_s[default]": 5.0}}
    md = bench.report(recs, s, timing, {"convert_s": {"3763": 3.0}, "render_s": {}}, {"default": s},
                      {"cpus": 2, "iters": 30, "threads": 1, "workers": 1, "resolution": 64})
    assert "Only 4 of the 8 objects ran" in md
    assert "| 100676 | Box | 4 | 3 | wrong | 9.000 | – | 7.000 | 9.420 | 8.030 |" in md
    assert "| 101326 | Eyeglasses | 2 | – | null |" in md and "101326: KeyError: 'size'" in md
    assert "| 3763 | null: conversion failed: boom |" in md and "| 3763 | 3 | – |" in md
    assert "| CD-w ≤ paper's on 100676 | 7.000 vs 8.030 | yes |" in md
    assert "| 100676 | lid_3 | rev | – | – | – |" in md


def test_bad_input_exits_2(bench, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("RSART_PARTNET_ROOT", raising=False)
    with pytest.raises(SystemExit) as e:
        bench.partnet_root(None)
    assert e.value.code == 2 and "RSART_PARTNET_ROOT" in capsys.readouterr().out
    with pytest.raises(SystemExit) as e:
        bench.partnet_root(tmp_path / "nope")
    assert e.value.code == 2
    assert bench.main(["--partnet", str(tmp_path), "--objects", "999"]) == 2
    assert bench.main(["--partnet", str(tmp_path), "--objects", "148", "--ablations", "bogus"]) == 2
