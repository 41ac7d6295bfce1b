"""Which rendered states an export uses, per capture protocol (rsart.render.protocols, docs/render.md).

* ``two-state`` (DTArt, ArtGS, REArtGS): the object's ``eval_states`` start and end, 100 train views each.
* ``single-joint`` (PARIS, ArticulatedGS): one run per movable joint — that joint at its minimum and at
  its maximum, every other joint at its ``start`` value — 100 train views per state.

The states must already be rendered in the object folder; otherwise :func:`require_captured` raises an
error carrying the exact ``rsart render`` command (the adapters never render by themselves: a render
takes minutes per object and writes into a dataset root the user chooses).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from rsart.dataset import RSArtObject, View
from rsart.errors import RsartError
from rsart.format import Joint, ObjectMeta, State

from .base import render_hint


@dataclass
class Run:
    """One run of a method: a ``start`` and an ``end`` state; ``joint`` is the moving joint (single-joint)."""

    name: str
    start: State
    end: State
    joint: Joint | None = None


def _same(a: dict[str, float], b: dict[str, float]) -> bool:
    return set(a) == set(b) and all(abs(a[k] - b[k]) <= 1e-9 for k in a)


def joint_range(meta: ObjectMeta, j: Joint) -> tuple[float, float]:
    """(min, max) of a joint as the single-joint protocol moves it (limits, or the multi-state span)."""
    if j.limits is not None:
        return j.limits
    a = meta.state(meta.eval_states["start"]).values[j.name]
    b = meta.state(meta.eval_states["end"]).values[j.name]
    return (min(a, b), max(a, b))


def _find_state(meta: ObjectMeta, j: Joint, extreme: str, values: dict[str, float]) -> State | None:
    for s in meta.states:
        if s.kind == "single" and s.joint == j.name and s.extreme == extreme and _same(s.values, values):
            return s
    for s in meta.states:
        if _same(s.values, values):
            return s  # e.g. a joint's minimum equals m0 and was merged into it
    return None


def protocol_runs(meta: ObjectMeta, protocol: str, object_dir: Path) -> list[Run]:
    """The runs of ``protocol`` for an object (raises with the render command when a state is missing)."""
    if protocol == "two-state":
        ev = meta.eval_states
        return [Run("two-state", meta.state(ev["start"]), meta.state(ev["end"]))]
    if protocol != "single-joint":
        raise RsartError(f"unknown protocol {protocol!r} (two-state | single-joint)")
    if not meta.joints:
        raise RsartError(f"{meta.object_id}: no joints, nothing to move for the single-joint protocol")
    base = meta.state(meta.eval_states["start"]).values
    runs = []
    for j in sorted(meta.joints, key=lambda j: j.child):
        lo, hi = joint_range(meta, j)
        found = []
        for extreme, v in (("min", lo), ("max", hi)):
            vals = dict(base)
            vals[j.name] = float(v)
            s = _find_state(meta, j, extreme, vals)
            if s is None:
                raise RsartError(f"{object_dir}: no state with joint {j.name!r} at its {extreme} ({v:g}) and the "
                                 f"others at start; render the single-joint protocol first:\n  "
                                 f"{render_hint(object_dir, 'single-joint')}")
            found.append(s)
        runs.append(Run(j.name, found[0], found[1], j))
    return runs


def require_captured(obj: RSArtObject, state_id: str, protocol: str, kinds: tuple[str, ...]) -> list[View]:
    """The views of a captured state, each with the image ``kinds`` present ("rgb", "depth", "mask")."""
    st = obj.states[state_id]
    if not st.captured:
        raise RsartError(f"{obj.path}: state {state_id!r} is not rendered (no states/{state_id}/cameras.json); "
                         f"render it first:\n  {render_hint(obj.path, protocol)}")
    views = st.views
    if not views:
        raise RsartError(f"{obj.path}: state {state_id!r} has no views")
    for v in views:
        for k in kinds:
            if not v.path(k).is_file():
                raise RsartError(f"{v.path(k)}: missing (state {state_id!r} view {v.id} needs its {k} image); "
                                 f"render it with:\n  {render_hint(obj.path, protocol)}")
    return views
