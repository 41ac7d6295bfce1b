"""Hide installed packages from a Python process, as if an rsart extra were not installed.

Put this folder first on PYTHONPATH and list top-level module names in RSART_HIDE (comma-separated):
every ``import NAME`` / ``import NAME.sub`` then raises ``ModuleNotFoundError`` exactly as for a package
that was never installed, and ``importlib.util.find_spec`` reports it absent. Used by the tests that run
real CLIs in subprocesses with an extra hidden (tests/rsart/test_extras.py).
"""
import importlib.abc
import os
import sys

_HIDDEN = {m.strip() for m in os.environ.get("RSART_HIDE", "").split(",") if m.strip()}


class _Hide(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in _HIDDEN:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None


if _HIDDEN:
    sys.meta_path.insert(0, _Hide())
