"""Which optional extra provides which package, and the one-line message when one is missing.

``pip install rsart`` is the core: the format, :func:`rsart.load`, validation, verify, procedural twins
and ``rsart-eval``. Everything heavy is an extra (``pip install 'rsart[render]'``); this module is the
one place that knows the map from importable module to extra, so every command says the same thing:

    >>> require("render", "rsart render")        # raises MissingExtra when pyrender/open3d are absent
    >>> Usd = imported("pxr.Usd", "usd")         # import a module of an extra, or raise MissingExtra

Each CLI also turns a stray ``ModuleNotFoundError`` for a module of an extra into the same one line
(:func:`from_import_error`), so no command ever ends in an ImportError traceback.
"""
from __future__ import annotations

import importlib
import importlib.util
from types import ModuleType

from .errors import RsartError

#: extra -> (pip requirement names as in pyproject, top-level modules it provides). pyproject.toml's
#: [project.optional-dependencies] holds the pins; tests/rsart/test_extras.py holds the two together.
EXTRAS: dict[str, tuple[str, ...]] = {
    "torch": ("torch",),
    "render": ("open3d", "pyrender", "OpenGL", "fast_simplification"),
    "usd": ("pxr",),
    "mujoco": ("mujoco",),
    "pd2gs": ("torch", "numba", "sklearn", "imageio"),
    "capture": ("pycolmap", "rosbags"),
    "server": ("fastapi", "uvicorn", "sqlalchemy", "multipart", "httpx"),
    "ray": ("ray",),
}

#: What each extra is for (``rsart doctor`` prints it).
PURPOSE: dict[str, str] = {
    "torch": "torch datasets (RSArtObject.torch_dataset)",
    "render": "the capture simulator (rsart render), PartNet-Mobility/URDF conversion (open3d, pyrender, EGL/OSMesa)",
    "usd": "USD twins (read/write .usda, rsart convert usd)",
    "mujoco": "MuJoCo checks and MJCF export of twins",
    "pd2gs": "the reference method PD²GS (torch, numba, scikit-learn)",
    "capture": "real captures: COLMAP poses, ROS bags (pycolmap, rosbags)",
    "server": "the leaderboard submission server (fastapi, uvicorn, sqlalchemy)",
    "ray": "rendering and PD²GS runs on a Ray cluster",
}

#: top-level module -> the extra to name when it is missing (torch is both [torch] and [pd2gs]; name the small one).
MODULE_EXTRA: dict[str, str] = {}
for _extra, _mods in EXTRAS.items():
    for _m in _mods:
        MODULE_EXTRA.setdefault(_m, _extra)


class MissingExtra(RsartError):
    """A feature needs an optional extra that is not installed. ``str()`` is one line naming the pip command."""

    def __init__(self, extra: str, module: str | None = None, what: str | None = None):
        self.extra, self.module, self.what = extra, module, what
        need = f"{what} needs" if what else "this needs"
        missing = f" ({module} is not installed)" if module else ""
        super().__init__(f"{need} the '{extra}' extra{missing}: pip install 'rsart[{extra}]'")


def _spec_present(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a blocked or broken package counts as absent
        return False


def missing_modules(extra: str) -> list[str]:
    """Top-level modules of ``extra`` that cannot be found (without importing them)."""
    if extra not in EXTRAS:
        raise KeyError(f"unknown extra {extra!r}; known: {', '.join(EXTRAS)}")
    return [m for m in EXTRAS[extra] if not _spec_present(m)]


def has(extra: str) -> bool:
    """True when every module of ``extra`` can be found (cheap: nothing is imported)."""
    return not missing_modules(extra)


def require(extra: str, what: str | None = None, modules: tuple[str, ...] | None = None) -> None:
    """Raise :class:`MissingExtra` when ``extra`` (or just ``modules`` of it) is not installed.

    ``what`` names the feature in the message, e.g. ``"rsart render"``.
    """
    need = modules if modules is not None else EXTRAS[extra]
    for m in need:
        if not _spec_present(m):
            raise MissingExtra(extra, m, what)


def imported(module: str, extra: str | None = None, what: str | None = None) -> ModuleType:
    """``importlib.import_module(module)``, raising :class:`MissingExtra` when it (or a module of an extra it
    imports) is missing. ``extra`` defaults to the extra that provides ``module``'s top-level package."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as e:
        err = from_import_error(e, what)
        if err is None and extra is not None:
            err = MissingExtra(extra, e.name, what)
        if err is None:
            raise
        raise err from None


def from_import_error(e: BaseException, what: str | None = None) -> MissingExtra | None:
    """The :class:`MissingExtra` for an ``ImportError`` of a module some extra provides, else None."""
    if isinstance(e, MissingExtra):
        return e
    name = getattr(e, "name", None)
    if not isinstance(e, ImportError) or not name:
        return None
    top = name.split(".")[0]
    extra = MODULE_EXTRA.get(top)
    return MissingExtra(extra, top, what) if extra else None
