"""Result store: ingest real rsart-eval outputs, idempotency, failures kept as failures, tracks, CLI."""
from __future__ import annotations

import json
import shutil
import subprocess

import pytest
from sqlalchemy import select

from leaderboards import schema as S
from leaderboards.schema import open_engine
from leaderboards.store import StoreError, add_scores, list_submissions, split_metric
from leaderboards.tracks import derive_track
from lb_helpers import PY, REPO, env


def test_ingest_is_idempotent_and_values_match_scores_json(scored, tmp_path):
    eng = open_engine(str(tmp_path / "lb.db"))
    sid, created = add_scores(eng, scored["gt"])
    assert created
    sid2, created2 = add_scores(eng, scored["gt"] / "scores.json")
    assert (sid2, created2) == (sid, False)
    # a copy elsewhere (same scores) is still the same submission
    shutil.copytree(scored["gt"], tmp_path / "copy")
    assert add_scores(eng, tmp_path / "copy") == (sid, False)
    subs = list_submissions(eng)
    assert len(subs) == 1
    doc = json.loads((scored["gt"] / "scores.json").read_text())
    s = subs[0]
    assert s.method_name == "ground-truth" and s.dataset_name == "tiny" and s.dataset_version == "1"
    assert s.config_hash == doc["config_hash"] and s.toolkit_version == doc["toolkit"]["version"]
    for cat, c in doc["aggregate"]["categories"].items():
        for m, a in c["metrics"].items():
            assert s.agg[cat][m][0] == a["mean"], (cat, m)
    assert s.agg[S.MEAN]["cd_w"][0] == doc["aggregate"]["overall"]["mean_of_categories"]["cd_w"]["mean"]
    with eng.connect() as c:
        rows = c.execute(select(S.scores).where(S.scores.c.submission_id == sid)).mappings().all()
    obj = doc["objects"]["drawer-0000"]
    got = {(r["object_id"], r["part_index"], r["metric"], r["state"]): r["value"] for r in rows}
    assert got[("drawer-0000", None, "cd_s", "start")] == obj["metrics"]["cd_s_start"]
    assert got[("drawer-0000", None, "cd_s", "mean")] == obj["metrics"]["cd_s"]
    assert got[("drawer-0000", 0, "axis_ang", "")] == obj["parts"][0]["metrics"]["axis_ang"]
    st = obj["eval_states"]["start"]
    assert got[("drawer-0000", None, "cd_w", st)] == obj["chamfer_by_state"][f"cd_w@{st}"]


def test_failed_objects_are_stored_as_failures(scored, tmp_path):
    eng = open_engine(str(tmp_path / "lb.db"))
    sid, _ = add_scores(eng, scored["failed"])
    s = list_submissions(eng)[0]
    assert s.n_failed_objects == 1
    assert s.agg["door"]["cd_s"] == (None, 0, 1)
    with eng.connect() as c:
        fails = c.execute(select(S.scores).where(S.scores.c.submission_id == sid, S.scores.c.failed.is_(True))
                          ).mappings().all()
    assert fails and all(r["value"] is None and r["reason"] for r in fails)
    assert {r["object_id"] for r in fails} == {"door-0001"}


def test_distinct_scores_are_distinct_entries(scored, tmp_path):
    eng = open_engine(str(tmp_path / "lb.db"))
    ids = {add_scores(eng, scored[k])[0] for k in ("gt", "perturbed", "failed")}
    assert len(ids) == 3
    names = {s.method_name for s in list_submissions(eng)}
    assert names == {"ground-truth", "perturbed", "half-failed"}
    pert = next(s for s in list_submissions(eng) if s.method_name == "perturbed")
    assert pert.agg[S.MEAN]["axis_ang"][0] == pytest.approx(5.0, abs=1e-6)


def test_bad_inputs_name_the_file(tmp_path):
    eng = open_engine(str(tmp_path / "lb.db"))
    with pytest.raises(StoreError, match="no scores.json"):
        add_scores(eng, tmp_path)
    (tmp_path / "scores.json").write_text("{not json")
    with pytest.raises(StoreError, match="not a JSON"):
        add_scores(eng, tmp_path)
    (tmp_path / "scores.json").write_text(json.dumps({"format": "rsart-scores/1", "toolkit": {"version": "1"}}))
    with pytest.raises(StoreError, match="missing field config_hash"):
        add_scores(eng, tmp_path)


def test_split_metric():
    assert split_metric("cd_s_start") == ("cd_s", "start")
    assert split_metric("cd_m") == ("cd_m", "mean")
    assert split_metric("cd_w@m3") == ("cd_w", "m3")
    assert split_metric("axis_ang") == ("axis_ang", "")
    assert split_metric("part_motion_rev") == ("part_motion_rev", "")


@pytest.mark.parametrize("method,expected", [
    ({"name": "PD2GS", "inputs": ["rgb"], "camera_poses": "gt", "states_used": 4,
      "discovery": {"counter": "vlm"}}, ("gt", "N", "inferred", "rgb")),
    ({"name": "DTArt", "inputs": ["rgb", "depth"], "camera_poses": "gt", "states_used": 2},
     ("gt", "2", "unspecified", "rgbd")),
    ({"name": "x", "inputs": ["rgb"], "camera_poses": "colmap", "states_used": "all", "part_count": "given"},
     ("estimated", "N", "given", "rgb")),
    ({"name": "ground-truth", "inputs": ["ground-truth"], "camera_poses": "gt"}, ("gt", "unspecified", "given", "gt")),
    ({"name": "bare"}, ("unspecified",) * 4),
    ("not a dict", ("unspecified",) * 4),
])
def test_tracks(method, expected):
    t = derive_track(method)
    assert (t.camera_poses, t.states, t.part_count, t.inputs) == expected


def test_cli_add_twice_and_bad_input(scored, tmp_path):
    db = str(tmp_path / "cli.db")
    run = lambda *a: subprocess.run([PY, "-m", "leaderboards.cli", *a], capture_output=True, text=True, cwd=REPO,
                                    env=env())
    r1 = run("add", str(scored["gt"]), "--db", db)
    r2 = run("add", str(scored["gt"]), "--db", db)
    assert r1.returncode == 0 and "added as submission 1" in r1.stdout
    assert r2.returncode == 0 and "already stored as submission 1" in r2.stdout
    bad = run("add", str(tmp_path / "missing"), "--db", db)
    assert bad.returncode == 2 and "no scores.json" in bad.stderr and "Traceback" not in bad.stderr
    assert len(list_submissions(open_engine(db))) == 1


def test_sqlite_runs_in_wal_mode(tmp_path):
    eng = open_engine(str(tmp_path / "w.db"))
    with eng.connect() as c:
        assert c.exec_driver_sql("PRAGMA journal_mode").scalar().lower() == "wal"


def test_penalised_means_run_label_and_an_older_store_gets_the_new_columns(scored, tmp_path):
    from sqlalchemy import text

    db = str(tmp_path / "lb.db")
    eng = open_engine(db)
    with eng.begin() as c:  # a store written before these columns existed
        for t, cols in (("aggregates", ("penalised", "completion")),
                        ("submissions", ("run_label", "run_config_hash", "units", "completion"))):
            for col in cols:
                c.execute(text(f"ALTER TABLE {t} DROP COLUMN {col}"))
    eng.dispose()
    eng = open_engine(db)  # adds them back
    add_scores(eng, scored["failed"], label="first try")
    s = list_submissions(eng)[0]
    doc = json.loads((scored["failed"] / "scores.json").read_text())
    mc = doc["aggregate"]["overall"]["mean_of_categories"]
    assert s.pen[S.MEAN]["axis_ang"] == (mc["axis_ang"]["penalised_mean"], mc["axis_ang"]["completion"])
    assert s.pen[S.MEAN]["axis_ang"][0] == pytest.approx(45.0, abs=1e-6)  # (door null: 90 + drawer 0) / 2
    assert s.completion == 0.5 and s.run == "first try" and len(s.run_config_hash) == 64
