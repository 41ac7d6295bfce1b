"""Dependencies point one way: no module of the rsart package imports pd2gs, baselines_adapters,
capture_tools or leaderboards (they plug into the CLI through entry points only)."""
import ast
from pathlib import Path

import pytest

import rsart

pytestmark = pytest.mark.core  # runs on the core install alone (.ci/core)

FORBIDDEN = {"pd2gs", "baselines_adapters", "capture_tools", "leaderboards"}


def test_rsart_imports_none_of_the_other_packages():
    root = Path(rsart.__file__).parent
    offenders = []
    for f in sorted(root.rglob("*.py")):
        tree = ast.parse(f.read_text(encoding="utf-8"), filename=str(f))
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) == \
                    "import_module" and node.args and isinstance(node.args[0], ast.Constant):
                names = [str(node.args[0].value)]
            offenders += [f"{f.relative_to(root.parent)}:{node.lineno} imports {n}" for n in names
                          if n.split(".")[0] in FORBIDDEN]
    assert offenders == [], "\n".join(offenders)
