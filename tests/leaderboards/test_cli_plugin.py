"""``rsart leaderboard`` arrives through the ``rsart.commands`` entry-point group (rsart imports no leaderboards).

A test distribution (a dist-info folder on PYTHONPATH) declares the entry point the way rsart's pyproject does.
"""
from __future__ import annotations

import subprocess
import textwrap

from lb_helpers import PY, REPO, env


def _dist(tmp_path, value: str):
    site = tmp_path / "site"
    dist = site / "rsart_leaderboard_test-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: rsart-leaderboard-test\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(textwrap.dedent(f"""\
        [rsart.commands]
        leaderboard = {value}
        """))
    e = env()
    e["PYTHONPATH"] = f"{site}:{e['PYTHONPATH']}"
    return e


def test_rsart_leaderboard_via_entry_point(tmp_path, scored):
    e = _dist(tmp_path, "leaderboards.cli:register")
    r = subprocess.run([PY, "-m", "rsart", "leaderboard", "--help"], capture_output=True, text=True, cwd=REPO, env=e)
    assert r.returncode == 0, r.stderr
    for action in ("add", "build", "serve", "token"):
        assert action in r.stdout
    db = tmp_path / "lb.db"
    r = subprocess.run([PY, "-m", "rsart", "leaderboard", "add", str(scored["gt"]), "--db", str(db)],
                       capture_output=True, text=True, cwd=REPO, env=e)
    assert r.returncode == 0 and "added as submission 1" in r.stdout, r.stderr
    r = subprocess.run([PY, "-m", "rsart", "leaderboard", "build", "--db", str(db), "--out", str(tmp_path / "s"),
                        "--no-plots"], capture_output=True, text=True, cwd=REPO, env=e)
    assert r.returncode == 0 and (tmp_path / "s" / "index.html").is_file(), r.stderr


def test_rsart_does_not_import_leaderboards():
    # importing rsart (and its CLI module) imports no leaderboards code; the `leaderboard` subcommand is
    # reached only through the rsart.commands entry point, loaded when the parser is built
    r = subprocess.run([PY, "-c", "import sys, rsart, rsart.cli, rsart.evaluation; "
                        "print('leaderboards' in sys.modules)"],
                       capture_output=True, text=True, cwd=REPO, env=env())
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "False"


def test_broken_plugin_is_reported_not_fatal(tmp_path):
    e = _dist(tmp_path, "no_such_module_xyz:register")
    r = subprocess.run([PY, "-m", "rsart", "--help"], capture_output=True, text=True, cwd=REPO, env=e)
    assert r.returncode == 0
    assert "rsart.commands plug-in 'leaderboard'" in r.stderr and "failed" in r.stderr


def test_rsart_leaderboard_usage_names_the_script():
    r = subprocess.run([PY, "-m", "leaderboards.cli", "--help"], capture_output=True, text=True, cwd=REPO, env=env(),
                       timeout=120)
    assert r.returncode == 0 and r.stdout.startswith("usage: rsart-leaderboard [-h] ACTION")
    assert "rsart-leaderboard leaderboard" not in r.stdout
    r = subprocess.run([PY, "-m", "leaderboards.cli", "build", "--help"], capture_output=True, text=True, cwd=REPO,
                       env=env(), timeout=120)
    assert r.stdout.startswith("usage: rsart-leaderboard build") and "--all-runs" in r.stdout
