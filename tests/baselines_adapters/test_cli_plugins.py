"""The `rsart adapters | export | import` commands find adapters only through the entry-point group
`rsart.adapters`: a test distribution (dist-info on sys.path) declares the built-ins the way
pyproject.toml does, plus a third-party adapter and a broken one."""
from __future__ import annotations

import json
import sys
import textwrap

import pytest

from rsart.cli import main
from tests.baselines_adapters.ba_helpers import play_artgs, read_json

TOY = '''
from pathlib import Path

class ToyAdapter:
    name = "toy"
    title = "Toy"
    protocol = "two-state"
    description = "a third-party adapter registered by entry point"

    def export(self, object_dir, out_dir, *, frame="z-up", overwrite=False, **options):
        Path(out_dir).mkdir(parents=True)
        (Path(out_dir) / "toy.txt").write_text(str(object_dir))
        return "toy export done"

    def import_run(self, run_dir, object_dir, submission, **options):
        return "toy import done"
'''


@pytest.fixture
def plugins(tmp_path, monkeypatch):
    site = tmp_path / "site"
    dist = site / "rsart_adapters_test-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: rsart-adapters-test\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(textwrap.dedent("""\
        [rsart.adapters]
        artgs = baselines_adapters.artgs:ArtGSAdapter
        dtart = baselines_adapters.dtart:DTArtAdapter
        toy = toy_adapter:ToyAdapter
        broken = no_such_module_xyz:Adapter
        """))
    (site / "toy_adapter.py").write_text(TOY)
    monkeypatch.syspath_prepend(str(site))
    yield site
    sys.modules.pop("toy_adapter", None)


def test_list_shows_entry_point_adapters(plugins, capsys):
    assert main(["adapters", "list"]) == 0
    out = capsys.readouterr().out
    assert "toy" in out and "third-party" in out and "artgs" in out and "two-state" in out
    assert "broken" in out and "BROKEN" in out  # a broken plug-in is listed, not fatal


def test_third_party_adapter_runs(plugins, objects, tmp_path, capsys):
    assert main(["export", str(objects["cabinet/two-state"]), "--method", "toy", "--out", str(tmp_path / "t")]) == 0
    assert (tmp_path / "t" / "toy.txt").is_file() and "toy export done" in capsys.readouterr().out


def test_export_import_score_through_the_cli(plugins, objects, tmp_path, capsys):
    obj = objects["cabinet/two-state"]
    out = tmp_path / "scene"
    assert main(["export", str(obj), "--method", "artgs", "--out", str(out)]) == 0
    assert (out / "transforms_train_start.json").is_file() and "README.txt" in capsys.readouterr().out
    assert main(["export", str(obj), "--method", "artgs", "--out", str(out)]) == 2  # exists, no --overwrite
    run = play_artgs(out, tmp_path / "model")
    sub = tmp_path / "subs" / "artgs.json"
    assert main(["import", str(run), "--method", "artgs", "--object", "cabinet-0000", "--data", str(obj),
                 "--into", str(sub), "--method-version", "b11a0e1"]) == 0
    doc = read_json(sub)
    assert doc["format"] == "rsart-submission/1" and doc["method"]["version"] == "b11a0e1"
    from rsart.evaluation.cli import main as eval_main

    assert eval_main([str(sub), "--data", str(obj), "--out", str(tmp_path / "eval"), "--workers", "1"]) == 0
    scores = json.loads((tmp_path / "eval" / "scores.json").read_text())
    assert "cabinet-0000" in json.dumps(scores) and (tmp_path / "eval" / "summary.md").is_file()


def test_cli_errors_exit_2_without_traceback(plugins, objects, tmp_path, capsys):
    obj = objects["cabinet/two-state"]
    assert main(["import", str(tmp_path), "--method", "nope", "--object", str(obj), "--into", str(tmp_path / "s.json")]) == 2
    err = capsys.readouterr().err
    assert "no adapter 'nope'" in err and "artgs" in err and "Traceback" not in err
    assert main(["import", str(tmp_path / "missing"), "--method", "artgs", "--object", str(obj),
                 "--into", str(tmp_path / "s.json")]) == 2
    assert "run folder not found" in capsys.readouterr().err
    assert main(["export", str(obj), "--method", "broken", "--out", str(tmp_path / "b")]) == 2
    assert "failed to load" in capsys.readouterr().err
    assert main(["import", "x", "--method", "artgs", "--object", "cabinet-0000", "--into", str(tmp_path / "s.json")]) == 2
    assert "--data" in capsys.readouterr().err


def test_failed_object_and_one_method_per_file(plugins, objects, tmp_path, capsys):
    obj = objects["cabinet/two-state"]
    sub = tmp_path / "artgs.json"
    assert main(["import", "-", "--method", "artgs", "--object", str(obj), "--into", str(sub),
                 "--failed", "out of memory"]) == 0
    assert read_json(sub)["results"] == {"cabinet-0000": None}
    from rsart.evaluation import load_ground_truth, read_submission

    _, problems = read_submission(sub, load_ground_truth(obj))
    assert problems == []
    assert main(["import", "-", "--method", "dtart", "--object", str(obj), "--into", str(sub), "--failed", "x"]) == 2
    assert "one submission file per method" in capsys.readouterr().err
