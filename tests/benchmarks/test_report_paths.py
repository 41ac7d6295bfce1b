"""benchmarks/common.py's report_paths: a report's table and record never go to one file."""
from __future__ import annotations

import importlib.util
from pathlib import Path

COMMON = Path(__file__).resolve().parents[2] / "benchmarks" / "common.py"


def _common():
    spec = importlib.util.spec_from_file_location("bench_common", COMMON)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_report_paths_never_coincide(tmp_path):
    """`--out x.json` used to write the markdown table to x.json and then replace it with the record."""
    for name in ("r.md", "r.json", "r"):
        md, js = _common().report_paths(tmp_path / name)
        assert (md.name, js.name) == ("r.md", "r.json")
        assert md.parent == js.parent == tmp_path
