"""`pd2gs run` end to end on a tiny rendered object: the submission it writes is valid and rsart-eval scores it."""
import json
import subprocess
import sys

import pytest


@pytest.mark.slow
def test_pd2gs_run_writes_a_scorable_submission(tmp_path):
    from rsart.cli import main as rsart_main
    from rsart.sources.procedural.registry import generate
    from rsart.twin_io import write_object

    g = generate("storage", 1)
    write_object(g.twin, tmp_path / "twins" / g.object_id, object_id=g.object_id, category=g.category, source=g.source)
    assert rsart_main(["render", str(tmp_path / "twins" / g.object_id), "--protocol", "pd2gs", "--out",
                       str(tmp_path / "data"), "--size", "96x72", "--views", "6", "--test-views", "1",
                       "--background", "plain", "--workers", "1", "--no-progress"]) == 0
    r = subprocess.run([sys.executable, "-m", "pd2gs", "run", "--data", str(tmp_path / "data"), "--out",
                        str(tmp_path / "out"), "--iters", "40", "--size", "64x48", "--no-refine", "--quiet"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    sub = tmp_path / "out" / "submission" / "submission.json"
    doc = json.loads(sub.read_text())
    assert doc["format"] == "rsart-submission/1" and g.object_id in doc["results"]
    assert doc["method"]["name"] == "PD2GS" and doc["method"]["states_used"] == 4
    e = subprocess.run([sys.executable, "-m", "rsart.evaluation.cli", str(sub), "--data", str(tmp_path / "data"),
                        "--out", str(tmp_path / "scores"), "--chamfer-seeds", "0"], capture_output=True, text=True)
    assert e.returncode == 0, e.stderr[-2000:]
    scores = json.loads((tmp_path / "scores" / "scores.json").read_text())
    assert g.object_id in json.dumps(scores)
