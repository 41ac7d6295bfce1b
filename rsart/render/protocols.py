"""Capture protocols: which interaction states of an object are rendered, with how many views.

=============  ======================================================  ======  =====
protocol       states                                                  train   test
=============  ======================================================  ======  =====
pd2gs          the multi-part states of meta.json (m0..m3)              50      10
two-state      ``eval_states`` start and end                            100     10
single-joint   per joint: its min and max, other joints at the start    100     10
rs-art         every state of meta.json (multi and single)              ≥ 60*   6
unseen         held-out multi states at 1/6, 1/2, 5/6 of each range     0       20
=============  ======================================================  ======  =====

(*) ``max(60, ceil(401 / n_states))`` so an object gets more than 400 training views.
Train views follow one hand-held circle per state; test views are fixed per object (identical in
every state). States a protocol needs that meta.json lacks (unseen states, a single state that
``protocol_states`` merged into m0) are created and listed in :attr:`ProtocolPlan.new_states`, with
``extra["protocol"]`` naming the protocol that made them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction

from ..errors import RsartError
from ..format import ObjectMeta, State
from ..states import multi_values

PROTOCOLS = ("pd2gs", "two-state", "single-joint", "rs-art", "unseen")
UNSEEN_FRACTIONS = (1 / 6, 1 / 2, 5 / 6)
_DEFAULTS = {"pd2gs": (50, 10), "two-state": (100, 10), "single-joint": (100, 10), "rs-art": (60, 6), "unseen": (0, 20)}


@dataclass
class StatePlan:
    """One state to render: ``n_train`` path views then ``n_test`` fixed test views."""

    state: State
    n_train: int
    n_test: int

    @property
    def n_views(self) -> int:
        return self.n_train + self.n_test


@dataclass
class ProtocolPlan:
    """The states of one object under a protocol; ``new_states`` must be added to the output meta.json."""

    name: str
    states: list[StatePlan]
    new_states: list[State] = field(default_factory=list)

    @property
    def n_views(self) -> int:
        return sum(s.n_views for s in self.states)


def _same(a: dict[str, float], b: dict[str, float]) -> bool:
    return set(a) == set(b) and all(abs(a[k] - b[k]) <= 1e-9 for k in a)


def _find_or_make(meta: ObjectMeta, made: list[State], wanted: State) -> State:
    """An existing state with the same values as ``wanted`` (preferring the same id), else ``wanted`` (recorded)."""
    for s in list(meta.states) + made:
        if s.id == wanted.id:
            if not _same(s.values, wanted.values):
                raise RsartError(f"{meta.object_id}: state {s.id!r} exists with other joint values than "
                                 f"the {wanted.extra.get('protocol')} protocol needs")
            return s
    if wanted.kind == "single":
        for s in meta.states:
            if s.kind == "single" and s.joint == wanted.joint and s.extreme == wanted.extreme and _same(s.values, wanted.values):
                return s
    for s in meta.states:
        if _same(s.values, wanted.values) and wanted.kind == "single":
            return s  # e.g. a joint's min state equals m0 and was merged into it
    made.append(wanted)
    return wanted


def unseen_id(t: float) -> str:
    """State id of the unseen multi state at fraction ``t``: 1/6 -> "u1of6", 0.5 -> "u1of2"."""
    f = Fraction(t).limit_denominator(1000)
    return f"u{f.numerator}of{f.denominator}"


def plan_protocol(name: str, meta: ObjectMeta, views: int | None = None, test_views: int | None = None,
                  fractions: tuple[float, ...] = UNSEEN_FRACTIONS) -> ProtocolPlan:
    """The :class:`ProtocolPlan` of ``meta`` under protocol ``name`` (see the module table).

    ``views`` / ``test_views`` override the per-state train / test view counts.
    """
    if name not in PROTOCOLS:
        raise RsartError(f"unknown protocol {name!r} (choose from {', '.join(PROTOCOLS)})")
    n_train, n_test = _DEFAULTS[name]
    made: list[State] = []
    if name == "pd2gs":
        states = [s for s in meta.states if s.kind == "multi" and "protocol" not in s.extra]
        if not states:
            raise RsartError(f"{meta.object_id}: meta.json has no multi-part states for the pd2gs protocol")
    elif name == "two-state":
        states = [meta.state(meta.eval_states["start"]), meta.state(meta.eval_states["end"])]
    elif name == "single-joint":
        if not meta.joints:
            raise RsartError(f"{meta.object_id}: no joints, nothing to move for the single-joint protocol")
        base = meta.state(meta.eval_states["start"]).values
        states = []
        for j in sorted(meta.joints, key=lambda j: j.child):
            lo, hi = j.limits if j.limits is not None else _multi_range(meta, j.name)
            for extreme, v in (("min", lo), ("max", hi)):
                vals = dict(base)
                vals[j.name] = float(v)
                want = State(f"s{j.child}{extreme}", "single", vals, joint=j.name, extreme=extreme,
                             extra={"protocol": "single-joint"})
                states.append(_find_or_make(meta, made, want))
    elif name == "rs-art":
        states = [s for s in meta.states if "protocol" not in s.extra]
        n_train = max(n_train, math.ceil(401 / max(1, len(states))))
    else:  # unseen
        states = []
        for t in fractions:
            if not 0 < t < 1:
                raise RsartError(f"unseen fraction {t} must lie strictly between 0 and 1")
            want = State(unseen_id(t), "multi", multi_values(meta.joints, t),
                         extra={"protocol": "unseen", "fraction": float(t)})
            states.append(_find_or_make(meta, made, want))
    if views is not None:
        n_train = views
    if test_views is not None:
        n_test = test_views
    if n_train < 0 or n_test < 0 or n_train + n_test == 0:
        raise RsartError(f"protocol {name}: need a positive number of views (train {n_train}, test {n_test})")
    seen: set[str] = set()
    plans = []
    for s in states:
        if s.id not in seen:
            seen.add(s.id)
            plans.append(StatePlan(s, n_train, n_test))
    return ProtocolPlan(name, plans, made)


def _multi_range(meta: ObjectMeta, joint: str) -> tuple[float, float]:
    """(lower, upper) of an unlimited joint as its multi states span it (start -> end)."""
    a = meta.state(meta.eval_states["start"]).values[joint]
    b = meta.state(meta.eval_states["end"]).values[joint]
    return (min(a, b), max(a, b))
