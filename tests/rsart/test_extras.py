"""Optional extras: each missing extra gives one line naming `pip install 'rsart[X]'` (real CLIs, real
subprocesses, the extra's packages hidden by tests/rsart/hide_extras/sitecustomize.py), the extras map
agrees with pyproject.toml, and every --help imports none of the heavy packages (that is what keeps it
under a second)."""
from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from rsart.extras import EXTRAS, MissingExtra, from_import_error, require

REPO = Path(__file__).resolve().parents[2]
HIDE = Path(__file__).resolve().parent / "hide_extras"
#: Everything that is not core (what a core-only install lacks).
HEAVY = sorted({m for mods in EXTRAS.values() for m in mods})


def _run(args: list[str], hide: list[str], cwd: Path | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(HIDE), str(REPO)]), RSART_HIDE=",".join(hide),
               OMP_NUM_THREADS="1")
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, env=env, cwd=cwd, timeout=timeout)


def _one_line(p: subprocess.CompletedProcess, extra: str) -> str:
    assert p.returncode == 2, (p.returncode, p.stdout, p.stderr)
    assert "Traceback" not in p.stderr, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if "pip install" in ln]
    assert len(lines) == 1 and lines[0].rstrip().endswith(f"pip install 'rsart[{extra}]'"), p.stderr
    return lines[0]


@pytest.fixture(scope="module")
def drawer(tmp_path_factory) -> Path:
    """A generated twin (core only: every extra hidden, so this also checks that generate needs none)."""
    out = tmp_path_factory.mktemp("extras")
    p = _run(["-m", "rsart", "generate", "--category", "drawer", "--seed", "0", "--out", str(out)], hide=HEAVY)
    assert p.returncode == 0, p.stderr
    return out / "drawer-0000"


@pytest.mark.core
def test_extras_match_pyproject():
    """Every extra of rsart/extras.py is an extra of pyproject.toml, and [all] holds them all."""
    opt = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert set(EXTRAS) <= set(opt)
    assert opt["all"] == [f"rsart[{','.join(EXTRAS)}]"]
    core = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]
    heavy_pins = ("torch", "open3d", "pyrender", "mujoco", "usd-core", "pycolmap", "numba")
    assert not [d for d in core if d.lower().startswith(heavy_pins)], core


@pytest.mark.core
def test_missing_extra_message_is_one_line():
    e = MissingExtra("render", "open3d", "rsart render")
    assert str(e) == "rsart render needs the 'render' extra (open3d is not installed): pip install 'rsart[render]'"
    assert from_import_error(ModuleNotFoundError("No module named 'pxr.Usd'", name="pxr.Usd")).extra == "usd"
    assert from_import_error(ModuleNotFoundError("x", name="not_an_extra_module")) is None
    with pytest.raises(KeyError):
        require("nonsense")


@pytest.mark.core
@pytest.mark.parametrize("extra, hide, args", [
    ("render", ["open3d", "pyrender"], ["-m", "rsart", "render", "{obj}", "--out", "{tmp}/r"]),
    ("ray", ["ray"], ["-m", "rsart", "render", "{obj}", "--out", "{tmp}/r", "--backend", "ray"]),
    ("usd", ["pxr"], ["-m", "rsart", "convert", "usd", "{tmp}/twin.usda", "--out", "{tmp}/u"]),
    ("pd2gs", ["torch", "numba"], ["-m", "pd2gs.cli", "run", "--data", "{obj}", "--out", "{tmp}/p"]),
    ("server", ["fastapi", "uvicorn"], ["-m", "leaderboards.cli", "serve", "--db", "{tmp}/db.sqlite",
                                        "--data", "{obj}", "--work", "{tmp}/w"]),
    ("capture", ["rosbags", "pycolmap"], ["-m", "rsart", "capture", "info", "{tmp}/rec.bag"]),
    ("torch", ["torch"], ["-c", "import sys, rsart\nfrom rsart.extras import MissingExtra\n"
                                "try:\n    rsart.load('{obj}').torch_dataset()\n"
                                "except MissingExtra as e:\n    print(e, file=sys.stderr); sys.exit(2)"]),
    ("mujoco", ["mujoco"], ["-c", "import sys\nfrom rsart.extras import MissingExtra\n"
                                  "from rsart.mujoco_check import load_mujoco\n"
                                  "try:\n    load_mujoco('{obj}/twin/object.urdf')\n"
                                  "except MissingExtra as e:\n    print(e, file=sys.stderr); sys.exit(2)"]),
])
def test_hidden_extra_gives_one_line(extra, hide, args, drawer, tmp_path):
    (tmp_path / "rec.bag").write_bytes(b"")
    (tmp_path / "twin.usda").write_text("#usda 1.0\n")
    args = [a.format(obj=drawer, tmp=tmp_path) for a in args]
    line = _one_line(_run(args, hide=hide), extra)
    assert f"'{extra}' extra" in line


@pytest.mark.core
def test_generate_without_usd_writes_urdf_only(drawer):
    assert (drawer / "twin" / "object.urdf").is_file()
    assert not (drawer / "twin" / "object.usda").exists()


HELP = [
    ["-m", "rsart", "--help"], ["-m", "rsart.evaluation.cli", "--help"], ["-m", "pd2gs.cli", "--help"],
    ["-m", "leaderboards.cli", "--help"],
    *[["-m", "rsart", c, "--help"] for c in ("validate", "verify", "info", "generate", "render", "show", "convert",
                                            "validate-submission", "adapters", "export", "import", "perturb",
                                            "doctor", "leaderboard", "capture")],
    *[["-m", "pd2gs.cli", c, "--help"] for c in ("train", "render", "eval", "run")],
    *[["-m", "leaderboards.cli", c, "--help"] for c in ("add", "build", "serve", "token")],
]


@pytest.mark.core
def test_every_help_imports_no_heavy_package():
    """--help of every command and subcommand, in one process each, leaves torch, trimesh, scipy, open3d,
    pyrender, pxr, mujoco, numba, cv2 ... unimported (they took 3-4 s before; the import is the cost)."""
    heavy = [*HEAVY, "trimesh", "scipy", "cv2", "matplotlib", "pandas"]
    probe = ("import runpy, sys\nsys.argv = [{mod!r}, *{rest!r}]\n"
             "try:\n    runpy.run_module({mod!r}, run_name='__main__')\nexcept SystemExit:\n    pass\n"
             "loaded = sorted({{m.split('.')[0] for m in sys.modules}} & set({heavy!r}))\n"
             "print('LOADED', ','.join(loaded), file=sys.stderr)")
    bad = {}
    for args in HELP:
        mod, rest = args[1], args[2:]
        p = _run(["-c", probe.format(mod=mod, rest=rest, heavy=heavy)], hide=[])
        assert "usage:" in p.stdout, (args, p.stdout, p.stderr)
        loaded = [ln for ln in p.stderr.splitlines() if ln.startswith("LOADED")][-1].split(" ", 1)[1].strip()
        if loaded:
            bad[" ".join(args[1:])] = loaded
    assert not bad, bad


@pytest.mark.core
def test_doctor_core_only_exits_0_and_names_missing_extras(tmp_path):
    """With every extra hidden, `rsart doctor` still exits 0 (the core works) and prints the pip command of
    each missing extra; the cache folder is RSART_CACHE's."""
    env_cache = tmp_path / "cache"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(HIDE), str(REPO)]), RSART_HIDE=",".join(HEAVY),
               RSART_CACHE=str(env_cache))
    p = subprocess.run([sys.executable, "-m", "rsart", "doctor"], capture_output=True, text=True, env=env,
                       timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    for extra in EXTRAS:
        assert f"pip install 'rsart[{extra}]'" in p.stdout, (extra, p.stdout)
    assert "rendering" in p.stdout and "pip install 'rsart[render]'" in p.stdout
    assert "cache folder" in p.stdout and str(env_cache) in p.stdout
    assert "core works" in p.stdout
    assert not env_cache.exists()  # the doctor writes nothing


@pytest.mark.gl
def test_doctor_renders_one_frame():
    """With the full install, the 1-frame GL test on EGL or OSMesa really renders pixels."""
    from rsart.doctor import gl_check

    pytest.importorskip("pyrender")
    checks = [gl_check(p) for p in ("egl", "osmesa")]
    assert any(c.ok for c in checks), [c.detail for c in checks]
