"""The RS-Art interaction-state protocol: which joint configurations an object is captured in.

* ``m0``..``m{n-1}`` (kind ``multi``): every movable joint together at fractions 0, 1/(n-1), ..., 1
  of its range (lower -> upper), evenly spaced (the paper: closed ... fully open).
* ``s{part}{min|max}`` (kind ``single``): the joint of movable part ``part`` at its lower/upper
  limit, every other joint at its ``m0`` value. A single state identical to an earlier state
  (e.g. ``s1min`` when the lower limit is the ``m0`` value) is dropped.
* ``eval_states`` = ``{start: m0, end: m{n-1}}``.

Joints without limits (URDF ``continuous``) use ``unlimited_range`` (default a quarter turn) and
record it in ``State.extra``.
"""
from __future__ import annotations

import math

from .format import Joint, State

QUARTER_TURN = (0.0, math.pi / 2)


def joint_range(j: Joint, unlimited_range: tuple[float, float] = QUARTER_TURN) -> tuple[float, float]:
    """(lower, upper) used for states: the limits, or ``unlimited_range`` for an unlimited revolute joint."""
    return j.limits if j.limits is not None else unlimited_range


def multi_values(joints: list[Joint], t: float, unlimited_range: tuple[float, float] = QUARTER_TURN) -> dict[str, float]:
    """Every joint at fraction ``t`` in [0, 1] of its range (t may be any value in between: unseen states)."""
    out = {}
    for j in joints:
        lo, hi = joint_range(j, unlimited_range)
        out[j.name] = float(lo + t * (hi - lo))
    return out


def protocol_states(joints: list[Joint], n_multi: int = 4,
                    unlimited_range: tuple[float, float] = QUARTER_TURN) -> tuple[list[State], dict[str, str]]:
    """The RS-Art states of an object with ``joints`` and its ``eval_states`` (see module docstring)."""
    states: list[State] = []
    seen: list[dict[str, float]] = []

    def add(s: State) -> None:
        key = {k: round(v, 12) for k, v in s.values.items()}
        if key in seen:
            return
        seen.append(key)
        states.append(s)

    for k in range(n_multi):
        add(State(f"m{k}", "multi", multi_values(joints, k / (n_multi - 1), unlimited_range)))
    base = multi_values(joints, 0.0, unlimited_range)
    for j in sorted(joints, key=lambda j: j.child):
        lo, hi = joint_range(j, unlimited_range)
        for extreme, v in (("min", lo), ("max", hi)):
            vals = dict(base)
            vals[j.name] = float(v)
            extra = {"unlimited_range": list(unlimited_range)} if j.limits is None else {}
            add(State(f"s{j.child}{extreme}", "single", vals, joint=j.name, extreme=extreme, extra=extra))
    return states, {"start": "m0", "end": f"m{n_multi - 1}"}
