"""``rsart doctor``: what this install can do, and how to get what it cannot.

Reports the Python and package versions, which extras (:mod:`rsart.extras`) are present, whether
headless rendering works on EGL and on OSMesa (a 1-frame render of a box in a subprocess with a
timeout, so a broken GL driver can neither hang nor crash the doctor), whether torch and numba load,
the CPU cores, the GPU and gsplat, and the cache folder (``$RSART_CACHE``, else
``$XDG_CACHE_HOME/rsart``, else ``~/.cache/rsart``; the folder :func:`rsart.load` caches converted
sources in). Nothing is written anywhere. The core works when ``import rsart`` and the core packages
load; that is the exit status (0 = core works, 1 = it does not).
"""
from __future__ import annotations

import importlib.metadata as md
import os
import platform
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from .extras import EXTRAS, PURPOSE, missing_modules

#: Core distributions (pyproject's [project.dependencies]) checked by import name.
CORE = {"numpy": "numpy", "scipy": "scipy", "trimesh": "trimesh", "yourdfpy": "yourdfpy",
        "opencv-contrib-python-headless": "cv2", "pandas": "pandas", "matplotlib": "matplotlib",
        "pillow": "PIL", "manifold3d": "manifold3d"}
#: Distributions whose versions are listed when installed.
PACKAGES = [*CORE, "torch", "numba", "open3d-cpu", "open3d", "pyrender2", "pyrender", "PyOpenGL", "usd-core",
            "mujoco", "pycolmap", "rosbags", "fastapi", "ray", "gsplat"]

#: 1-frame render of a unit box at 32x32 with pyrender; prints the number of non-background pixels.
_GL_PROBE = """
import numpy as np, pyrender, trimesh
r = pyrender.OffscreenRenderer(32, 32)
s = pyrender.Scene(bg_color=[0, 0, 0, 0], ambient_light=[1, 1, 1])
s.add(pyrender.Mesh.from_trimesh(trimesh.creation.box(extents=(1, 1, 1))))
pose = np.eye(4); pose[2, 3] = 3.0
s.add(pyrender.IntrinsicsCamera(32, 32, 16, 16), pose=pose)
color, depth = r.render(s)
r.delete()
print(int((depth > 0).sum()))
"""


@dataclass
class Check:
    """One line of the report: ``ok`` True/False (None = informational), a label and what was found."""

    label: str
    ok: bool | None
    detail: str


def _version(dist: str) -> str | None:
    try:
        return md.version(dist)
    except md.PackageNotFoundError:
        return None


def _subprocess(code: str, env: dict | None = None, timeout: float = 30.0) -> tuple[bool, str]:
    """Run ``code`` in a fresh interpreter; (succeeded, last line of output or the reason it failed)."""
    try:
        p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout,
                           env=dict(os.environ, **(env or {})))
    except subprocess.TimeoutExpired:
        return False, f"timed out after {timeout:.0f} s"
    except OSError as e:
        return False, str(e)
    out = (p.stdout.strip().splitlines() or [""])[-1]
    if p.returncode != 0:
        err = [ln for ln in p.stderr.strip().splitlines() if ln.strip()]
        return False, (err[-1] if err else f"exit status {p.returncode}")[:200]
    return True, out


def gl_check(platform_name: str, timeout: float = 30.0) -> Check:
    """Render one frame with pyrender on ``platform_name`` ("egl" | "osmesa") in a subprocess."""
    ok, out = _subprocess(_GL_PROBE, {"PYOPENGL_PLATFORM": platform_name, "MUJOCO_GL": platform_name}, timeout)
    if ok and out.isdigit() and int(out) > 0:
        return Check(f"rendering ({platform_name})", True, f"works (1 frame, {out} pixels hit)")
    return Check(f"rendering ({platform_name})", False, out if not ok else f"rendered an empty frame ({out})")


def cache_dir() -> Path:
    """The cache folder rsart.load uses: ``$RSART_CACHE``, else ``$XDG_CACHE_HOME/rsart``, else ``~/.cache/rsart``."""
    try:  # the loader's own rule, where this rsart has it
        from .sources.cache import default_cache
    except ImportError:
        if os.environ.get("RSART_CACHE"):
            return Path(os.environ["RSART_CACHE"]).expanduser()
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        return Path(base) / "rsart"
    return default_cache()


def _cache_check() -> Check:
    d = cache_dir()
    probe = d
    while not probe.exists() and probe != probe.parent:  # the folder is made on first use: check its parent
        probe = probe.parent
    if probe.is_dir() and os.access(probe, os.W_OK | os.X_OK):
        return Check("cache folder", True, f"{d} (writable{'' if d.exists() else ', created on first use'}; "
                                           "set RSART_CACHE to move it)")
    return Check("cache folder", False, f"{d} is not writable (set RSART_CACHE to a writable folder)")


def run_checks(gl: bool = True, gl_timeout: float = 30.0) -> tuple[list[Check], bool]:
    """Every check of the report, and whether the core works."""
    checks = [Check("python", None, f"{platform.python_version()} ({sys.executable})"),
              Check("platform", None, f"{platform.platform()}")]
    from . import __version__

    checks.append(Check("rsart", None, f"{__version__} ({Path(__file__).parent})"))
    core_ok = True
    for dist, mod in CORE.items():
        if missing_modules_of(mod):
            core_ok = False
            checks.append(Check(f"core: {dist}", False, "missing: reinstall with pip install rsart"))
    try:
        import rsart  # noqa: F401
        import rsart.evaluation.score  # noqa: F401  (the scorer: numpy, scipy, trimesh)
    except Exception as e:  # any failure here means the core is broken; say which
        core_ok = False
        checks.append(Check("core import", False, f"{type(e).__name__}: {e}"))
    else:
        checks.append(Check("core", core_ok, "load, validate, verify, generate, rsart-eval"))
    versions = [f"{d} {v}" for d in PACKAGES if (v := _version(d))]
    checks.append(Check("packages", None, ", ".join(versions)))
    for extra in EXTRAS:
        miss = missing_modules(extra)
        checks.append(Check(f"extra [{extra}]", not miss,
                            PURPOSE[extra] if not miss else
                            f"missing {', '.join(miss)}: pip install 'rsart[{extra}]' for {PURPOSE[extra]}"))
    for mod, extra in (("torch", "torch"), ("numba", "pd2gs")):
        if missing_modules_of(mod):
            checks.append(Check(f"{mod} loads", False, f"not installed: pip install 'rsart[{extra}]'"))
            continue
        ok, out = _subprocess(f"import {mod}; print({mod}.__version__)", timeout=120)
        checks.append(Check(f"{mod} loads", ok, out))
    checks.append(Check("cpu cores", None, f"{os.cpu_count()} (usable: {len(os.sched_getaffinity(0))})"
                        if hasattr(os, "sched_getaffinity") else f"{os.cpu_count()}"))
    checks.append(_gpu_check())
    gs = _version("gsplat")
    checks.append(Check("gsplat", None, f"{gs} (pd2gs --backend gsplat)" if gs else
                        "not installed (optional CUDA rasteriser for pd2gs; the CPU backends need none)"))
    if gl:
        if missing_modules_of("pyrender") or missing_modules_of("OpenGL"):
            checks.append(Check("rendering", False, "pyrender not installed: pip install 'rsart[render]'"))
        else:
            checks += [gl_check(p, gl_timeout) for p in ("egl", "osmesa")]
    checks.append(_cache_check())
    return checks, core_ok


def missing_modules_of(module: str) -> bool:
    """True when ``module`` cannot be found (nothing is imported)."""
    import importlib.util

    try:
        return importlib.util.find_spec(module) is None
    except (ImportError, ValueError):
        return True


def _gpu_check() -> Check:
    """A CUDA GPU as torch sees it (in a subprocess), else as nvidia-smi sees it; informational."""
    if not missing_modules_of("torch"):
        ok, out = _subprocess("import torch; print(torch.cuda.get_device_name(0) if torch.cuda.is_available() "
                              "else 'none')", timeout=120)
        if ok:
            return Check("gpu", None, f"{out} (torch)" if out != "none" else "none visible to torch (CPU is enough)")
    try:
        p = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                           text=True, timeout=20)
        if p.returncode == 0 and p.stdout.strip():
            return Check("gpu", None, f"{p.stdout.strip().splitlines()[0]} (nvidia-smi)")
    except (OSError, subprocess.TimeoutExpired):
        pass
    return Check("gpu", None, "none found (CPU is enough)")


def format_report(checks: list[Check]) -> str:
    """The report as text: one line per check, ``ok`` / ``--`` (missing or failing) / blank (information)."""
    mark = {True: "ok", False: "--", None: "  "}
    width = max(len(c.label) for c in checks)
    return "\n".join(f"{mark[c.ok]}  {c.label:<{width}}  {c.detail}" for c in checks)
