"""``rsart-eval`` and ``rsart validate-submission`` as real subprocesses: exit codes, outputs, no tracebacks."""
from __future__ import annotations

import json
import re
import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

pytestmark = pytest.mark.core  # runs on the core install alone (.ci/core)

REPO = Path(__file__).resolve().parents[3]


def run(*args, module="rsart.evaluation.cli"):
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", module, *map(str, args)], capture_output=True, text=True,
                          env=env, timeout=300)


def test_make_gt_submission_then_score_it(dataset, tmp_path):
    r = run("--make-gt-submission", "--data", dataset, "--out", tmp_path / "gt")
    assert r.returncode == 0, r.stderr
    sub = tmp_path / "gt" / "submission.json"
    out = tmp_path / "scores"
    r = run(sub, "--data", dataset, "--out", out, "--workers", "2", "--chamfer-samples", "2000")
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    for f in ("scores.json", "scores_per_part.csv", "scores_per_object.csv", "summary.md", "summary.png"):
        assert (out / f).is_file() and (out / f).stat().st_size > 0, f
    s = json.loads((out / "scores.json").read_text(), parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
    assert s["submission"]["method"]["name"] == "ground-truth"
    assert s["dataset"] == {"name": "tiny", "version": "1", "split": None, "root": str(dataset)}
    assert s["config"]["chamfer"]["n_samples"] == 2000 and s["config"]["chamfer"]["component_filter"] is True
    assert len(s["config_hash"]) == 64 and s["toolkit"]["name"] == "rsart"
    parts = pd.read_csv(out / "scores_per_part.csv")
    assert len(parts) == 6  # 3 objects x 2 movable parts
    objs = pd.read_csv(out / "scores_per_object.csv")
    assert list(objs["object_id"]) == ["cabinet-0000", "cabinet-0001", "lamp-0000"]
    assert (objs["axis_ang"].abs() < 1e-9).all()
    md = (out / "summary.md").read_text()
    table = md.split("| Metric")[1].split("\n\n")[0]
    assert "| Metric | lamp | storage | Mean | Penalised mean | Completion |" in md
    assert not re.search(r"\d\*|\| \* \|", table) and "| 100 % |" in table
    assert (out / "summary.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_perturbed_submission_via_cli(dataset, tmp_path):
    r = run("--make-gt-submission", "--data", dataset, "--split", "lamps", "--out", tmp_path / "p",
            "--perturb-joints", "axis=5deg,seed=3")
    assert r.returncode == 0, r.stderr
    assert "deprecated" not in r.stderr
    # the old spelling still works and says so
    old = run("--make-gt-submission", "--data", dataset, "--split", "lamps", "--out", tmp_path / "p_old",
              "--perturb", "axis=5deg,seed=3")
    assert old.returncode == 0 and "--perturb is deprecated; use --perturb-joints" in old.stderr
    assert (json.loads((tmp_path / "p_old" / "submission.json").read_text())
            == json.loads((tmp_path / "p" / "submission.json").read_text()))
    out = tmp_path / "o"
    r = run(tmp_path / "p" / "submission.json", "--data", dataset, "--split", "lamps", "--out", out,
            "--workers", "1", "--chamfer-samples", "1000", "--chamfer-seeds", "0")
    assert r.returncode == 0, r.stderr
    objs = pd.read_csv(out / "scores_per_object.csv")
    assert abs(objs.loc[0, "axis_ang"] - 5.0) < 1e-6


def test_invalid_submissions_exit_2_without_traceback(dataset, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "rsart-submission/1", "method": {"name": "m"}, "dataset": {}, "results": {"x": NaN}}')
    r = run(bad, "--data", dataset, "--validate-only")
    assert r.returncode == 2 and "non-finite number NaN" in r.stderr and "Traceback" not in r.stderr
    bad.write_text('{"format": "rsart-submission/1", "method": {"name": "m"}, "dataset": {}, "results": {}}')
    r = run(bad, "--data", dataset)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    for oid in ("cabinet-0000", "cabinet-0001", "lamp-0000"):
        assert f"results.{oid}: missing object" in r.stderr
    r = run("validate-submission", bad, "--data", dataset, module="rsart")
    assert r.returncode == 2 and "results.lamp-0000: missing object" in r.stderr and "Traceback" not in r.stderr


def test_help_points_to_the_docs_not_the_design_notes():
    r = run("--help")
    assert r.returncode == 0 and "docs/evaluation.md" in r.stdout and "DESIGN" not in r.stdout
    assert "--perturb-joints" in r.stdout

