"""The rsart CLI: --help, validate, verify, info; errors without tracebacks."""
import json
import subprocess
import sys

import pytest

from rsart.verify import write_checksums

pytestmark = pytest.mark.core  # runs on the core install alone (.ci/core)


def rsart(*args):
    return subprocess.run([sys.executable, "-m", "rsart", *map(str, args)], capture_output=True, text=True)


def test_help_explains_conventions():
    r = rsart("--help")
    assert r.returncode == 0 and "OpenCV" in r.stdout and "millimetres" in r.stdout
    for cmd in ("validate", "verify", "info"):
        assert cmd in r.stdout


def test_validate_ok_and_bad(cabinet_dir):
    r = rsart("validate", cabinet_dir)
    assert r.returncode == 0, r.stderr
    meta = json.loads((cabinet_dir / "meta.json").read_text())
    meta["joints"][1]["axis"] = [0, 0, 0]
    meta["units"] = "furlong"
    (cabinet_dir / "meta.json").write_text(json.dumps(meta))
    r = rsart("validate", cabinet_dir / "meta.json")
    assert r.returncode == 2
    assert "joints[1].axis: zero-length vector" in r.stderr and "units:" in r.stderr
    assert "Traceback" not in r.stderr


def test_validate_bad_json_no_traceback(tmp_path):
    (tmp_path / "meta.json").write_text("{oops")
    r = rsart("validate", tmp_path / "meta.json")
    assert r.returncode == 2 and "invalid JSON" in r.stderr and "Traceback" not in r.stderr


def test_verify_exit_codes(cabinet_dir):
    r = rsart("verify", cabinet_dir)
    assert r.returncode == 2 and "no checksum file" in r.stderr and "Traceback" not in r.stderr
    write_checksums(cabinet_dir)
    assert rsart("verify", cabinet_dir).returncode == 0
    (cabinet_dir / "twin" / "parts" / "lid.ply").write_bytes(b"corrupt")
    r = rsart("verify", cabinet_dir)
    assert r.returncode == 1 and "corrupt: twin/parts/lid.ply" in r.stdout


def test_info(cabinet_dir):
    r = rsart("info", cabinet_dir)
    assert r.returncode == 0 and "drawer_slide: prismatic" in r.stdout
