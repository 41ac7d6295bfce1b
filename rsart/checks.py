"""The checks every rsart reader runs on decoded JSON and names: one home, one policy.

Policy (yourdfpy's single ``validate()`` is the model): a reader runs every check, each check adds
what is wrong to a :class:`~rsart.errors.Problems` under the value's JSON path (``joints[0].axis``)
and returns ``None``/``False`` instead of raising, and the reader raises one
:class:`~rsart.errors.ValidationError` listing all of them at the end. Messages quote the offending
value briefly, in JSON spelling (``null``, ``true``), strings quoted.

Used by :mod:`rsart.format` (meta/cameras/index), :mod:`rsart.evaluation.submission`, the
PartNet-Mobility and USD sources and :mod:`rsart.usd_read` (safe ids).
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from .errors import Problems

#: An id that is safe as a file or folder name: object ids, view ids, state ids.
SAFE_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,127}$")
SAFE_ID_RULE = "letters, digits, '_', '.', '-'; at most 128 characters"


def is_safe_id(v: Any) -> bool:
    """True for a string that matches :data:`SAFE_ID` (starts with a letter or digit, no separators)."""
    return isinstance(v, str) and SAFE_ID.match(v) is not None


def make_safe_id(text: str, default: str) -> str:
    """``text`` made a safe id: other characters become '_', leading '_', '.', '-' dropped, 128 at most;
    ``default`` when nothing is left (e.g. 'my door' -> 'my_door')."""
    return re.sub(r"[^A-Za-z0-9_.\-]", "_", text).lstrip("_.-")[:128] or default


def unique_name(base: str, taken: set[str]) -> str:
    """``base``, or ``base_1``, ``base_2``, ... : the first not in ``taken``, which is then added to it."""
    out, k = base, 1
    while out in taken:
        out = f"{base}_{k}"
        k += 1
    taken.add(out)
    return out


def brief(v: Any) -> str:
    """``v`` as a message quotes it: JSON spelling, strings in quotes, cut to 60 characters."""
    if isinstance(v, str):
        s = repr(v)
    else:
        try:
            s = json.dumps(v)
        except (TypeError, ValueError):  # not a JSON value (a numpy array, say): Python's spelling
            s = repr(v)
    return s if len(s) <= 60 else s[:57] + "..."


def kind(v: Any) -> str:
    """The JSON kind of ``v`` with its article: "an object", "a list", "a number", ..."""
    return {dict: "an object", list: "a list", str: "a string", bool: "a boolean", type(None): "null",
            int: "a number", float: "a number"}.get(type(v), type(v).__name__)


def is_num(v: Any) -> bool:
    """A JSON number (int or float, not a boolean), finite or not."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def is_finite_num(v: Any) -> bool:
    """A finite JSON number (not a boolean, not NaN or inf)."""
    return is_num(v) and math.isfinite(v)


def is_int(v: Any) -> bool:
    """A JSON integer (not a boolean)."""
    return isinstance(v, int) and not isinstance(v, bool)


def vector(pb: Problems, path: str, v: Any, n: int = 3, *, unit: bool = False,
           nonzero: bool = False) -> np.ndarray | None:
    """``v`` as an (n,) float64 array, or None with the problem added at ``path``.

    ``unit``: the norm must be 1 (within 1e-6); the result is renormalised. ``nonzero``: the norm
    must not be 0 (an axis that is normalised later).
    """
    if not isinstance(v, list) or len(v) != n:
        pb.add(path, f"expected a list of {n} numbers, got {kind(v)} {brief(v)}")
        return None
    if not all(is_num(x) for x in v):
        pb.add(path, f"expected {n} numbers, got {brief(v)}")
        return None
    if not all(math.isfinite(x) for x in v):
        pb.add(path, "non-finite number (NaN or inf)")
        return None
    a = np.asarray(v, dtype=np.float64)
    if unit or nonzero:
        nrm = float(np.linalg.norm(a))
        if nrm < 1e-12 or (nonzero and nrm < 1e-9):
            pb.add(path, "zero-length vector")
            return None
        if unit:
            if abs(nrm - 1.0) > 1e-6:
                pb.add(path, f"not a unit vector (norm {nrm:.6g})")
                return None
            a = a / nrm
    return a


def string(pb: Problems, path: str, v: Any, safe: bool = False) -> bool:
    """A non-empty string (``safe``: also a :data:`SAFE_ID`); else the problem is added at ``path``."""
    if not isinstance(v, str) or not v:
        pb.add(path, f"expected a non-empty string, got {brief(v)}")
        return False
    if safe and not SAFE_ID.match(v):
        pb.add(path, f"{v!r} is not a safe id ({SAFE_ID_RULE})")
        return False
    return True


def unique_id(pb: Problems, path: str, v: Any, seen: set[str], what: str) -> bool:
    """A safe id (:func:`string` with ``safe``) that ``seen`` does not hold yet (a repeat is a problem
    ``duplicate <what> ...``); ``seen`` collects it. False only when ``v`` is no safe id."""
    if not string(pb, path, v, safe=True):
        return False
    if v in seen:
        pb.add(path, f"duplicate {what} {v!r}")
    seen.add(v)
    return True


def relpath(pb: Problems, path: str, v: Any) -> bool:
    """A relative path that stays inside its folder (no absolute path, drive or ``..``)."""
    if not string(pb, path, v):
        return False
    if v.startswith(("/", "\\")) or re.match(r"^[A-Za-z]:", v) or ".." in Path(v).parts:
        pb.add(path, f"{v!r} must be a relative path inside the object folder")
        return False
    return True


def mapping(pb: Problems, path: str, v: Any, required: tuple[str, ...]) -> bool:
    """A JSON object; each ``required`` key that is missing is a problem of its own."""
    if not isinstance(v, dict):
        pb.add(path, f"expected an object, got {brief(v)}")
        return False
    for k in required:
        if k not in v:
            pb.add(f"{path}.{k}" if path else k, "missing")
    return True


def unknown_keys(pb: Problems, path: str, d: dict, known: tuple[str, ...]) -> None:
    """Each key of ``d`` outside ``known`` is a problem (for formats that allow no extra keys)."""
    for k in d:
        if k not in known:
            pb.add(f"{path}.{k}" if path else k, f"unknown key (allowed: {', '.join(known)})")


def extra(d: dict, known: tuple[str, ...]) -> dict:
    """The keys of ``d`` outside ``known`` (kept by readers and written back by writers)."""
    return {k: v for k, v in d.items() if k not in known}
