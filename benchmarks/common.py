"""What the benchmark scripts share: the machine they ran on, and writing their result file.

The scripts import rsart, pd2gs, ... like any user code: run them from the repository root with the
project installed (``pip install -e .``) or ``PYTHONPATH=.``; none of them edits ``sys.path``.
"""
from __future__ import annotations

import importlib.util
import os
import platform
from pathlib import Path
from types import ModuleType
from typing import Any

from rsart.io import dumps_json, write_json

REPO = Path(__file__).resolve().parents[1]


def load_avg() -> list[float]:
    """The 1, 5 and 15 minute load averages, rounded to 0.01 (the box is shared: say how busy it was)."""
    return [round(x, 2) for x in os.getloadavg()]


def machine(**extra: Any) -> dict:
    """cpus, python, platform and processor of this machine, plus ``extra`` keys (load averages, say)."""
    return {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform(),
            "processor": platform.processor(), **extra}


def write_result(path: str | os.PathLike, result: dict, echo: bool = False) -> None:
    """Write ``result`` to ``path`` as JSON, atomically (rsart's writer); print it too when ``echo``."""
    write_json(path, result)
    if echo:
        print(dumps_json(result), end="")


def test_helpers(relpath: str) -> ModuleType:
    """A helper module of the test tree (e.g. ``"leaderboards/lb_helpers.py"``), loaded from its file."""
    path = REPO / "tests" / relpath
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def select_split(data, oids: list[str], name: str) -> str:
    """Record ``oids`` as split ``name`` of the data root's index.json (checksums rewritten), so rsart-eval
    can score a subset: it wants every object of what it scores in the submission. -> ``name``."""
    from pathlib import Path

    from rsart.format import read_index, write_index
    from rsart.verify import write_checksums

    data = Path(data)
    idx = read_index(data / "index.json")
    if idx.splits.get(name) != list(oids):
        idx.splits[name] = list(oids)
        write_index(idx, data / "index.json")
        write_checksums(data)
    return name
