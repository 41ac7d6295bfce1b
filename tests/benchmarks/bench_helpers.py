"""Load a script of benchmarks/ as a module (the scripts are not a package), for the tests beside them."""
from __future__ import annotations

import importlib.util
import sys
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"


def load(script: str) -> ModuleType:
    """benchmarks/``script`` executed as a fresh module."""
    spec = importlib.util.spec_from_file_location(f"bench_{Path(script).stem}", BENCH / script)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@contextmanager
def on_path(script: str):
    """:func:`load` with benchmarks/ on sys.path while the module is in use, as when the script runs from there
    (scripts import their siblings, common and pd2gs_suite, some of them only when called)."""
    sys.path.insert(0, str(BENCH))
    try:
        yield load(script)
    finally:
        sys.path.remove(str(BENCH))
