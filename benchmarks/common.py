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

from rsart.io import atomic_write_text, dumps_json, write_json

REPO = Path(__file__).resolve().parents[1]


def load_avg() -> list[float]:
    """The 1, 5 and 15 minute load averages, rounded to 0.01 (the box is shared: say how busy it was)."""
    return [round(x, 2) for x in os.getloadavg()]


def cpu_description(cpuinfo: str | os.PathLike = "/proc/cpuinfo") -> str:
    """The processor in one line, e.g. ``"AMD EPYC (family 25 model 1), 2445 MHz, AVX2"``: the model name,
    family/model numbers, clock and widest AVX level of the first CPU in ``cpuinfo`` (Linux's format).
    Two machines both called "AMD EPYC" ran the CPU rasterizer 3.5x apart (one had AVX-512), so a timed
    result says which one it ran on. Falls back to ``platform.processor()`` or ``platform.machine()`` where
    there is no readable cpuinfo. (Hand-written: the file is "key : value" lines, and py-cpuinfo would be a
    new dependency for one header line.)"""
    fields: dict[str, str] = {}
    try:
        text = Path(cpuinfo).read_text(errors="replace")
    except OSError:
        text = ""
    for line in text.split("\n\n", 1)[0].splitlines():
        key, sep, value = line.partition(":")
        if sep:
            fields.setdefault(key.strip(), value.strip())
    name = fields.get("model name")
    if not name:
        return platform.processor() or platform.machine()
    if "cpu family" in fields and "model" in fields:
        name += f" (family {fields['cpu family']} model {fields['model']})"
    parts = [name]
    if "cpu MHz" in fields:
        try:
            parts.append(f"{float(fields['cpu MHz']):.0f} MHz")
        except ValueError:
            pass
    flags = set(fields.get("flags", "").split())
    level = next((lvl for flag, lvl in (("avx512f", "AVX-512"), ("avx2", "AVX2"), ("avx", "AVX")) if flag in flags), None)
    if level:
        parts.append(level)
    return ", ".join(parts)


def machine(**extra: Any) -> dict:
    """cpus, python, platform and processor of this machine (``cpu_description``), plus ``extra`` keys
    (load averages, say)."""
    return {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform(),
            "processor": cpu_description(), **extra}


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


def write_report(out: str | os.PathLike, table: str, record: dict) -> tuple[Path, Path]:
    """Write a benchmark report named by ``--out``: the markdown ``table`` to ``<out>.md`` and the ``record`` to
    ``<out>.json``, both atomically, whatever ``out``'s suffix (``--out x.json`` once wrote the table to x.json
    and then replaced it with the record). -> (markdown path, json path)."""
    out = Path(out)
    md_path, json_path = out.with_suffix(".md"), out.with_suffix(".json")
    md_path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(md_path, table)
    write_json(json_path, record)
    return md_path, json_path


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
