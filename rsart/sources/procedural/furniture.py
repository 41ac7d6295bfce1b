"""Shared furniture pieces for the category generators: carcasses with openings, drawers,
hinged panels (doors, lids, flaps), handles, and seeded material palettes.

Conventions: metres; world z up; the object's *front* faces -y. Every moving piece keeps a
clearance of at least ``GAP`` to its neighbours at every joint value within its limits.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import shapes as S
from .builder import ObjectBuilder
from .textures import Material

GAP = 0.003          # clearance between a moving part and its surroundings (m)
_UNIT = {"+x": (1, 0, 0), "-x": (-1, 0, 0), "+y": (0, 1, 0), "-y": (0, -1, 0), "+z": (0, 0, 1), "-z": (0, 0, -1)}

WOODS = [(0.72, 0.53, 0.34), (0.60, 0.40, 0.24), (0.83, 0.68, 0.48), (0.45, 0.30, 0.20), (0.88, 0.80, 0.66)]
PAINTS = [(0.93, 0.93, 0.90), (0.25, 0.32, 0.42), (0.70, 0.20, 0.18), (0.30, 0.50, 0.35), (0.85, 0.75, 0.35),
          (0.55, 0.60, 0.68), (0.20, 0.20, 0.22)]
METALS = [(0.75, 0.76, 0.78), (0.60, 0.61, 0.63), (0.78, 0.66, 0.42), (0.30, 0.30, 0.32)]


class Palette:
    """Seeded material factory: each call returns a new Material with its own texture seed."""

    def __init__(self, rng: np.random.Generator):
        self.rng = rng
        self._n = 0

    def _seed(self) -> int:
        self._n += 1
        return int(self.rng.integers(0, 2**31 - 1))

    def pick(self, choices: list) -> tuple[float, float, float]:
        return tuple(choices[int(self.rng.integers(len(choices)))])

    def make(self, name: str, kind: str, color=None, **params) -> Material:
        if color is None:
            color = self.pick({"wood": WOODS, "metal": METALS}.get(kind, PAINTS))
        return Material(name, kind, tuple(float(c) for c in color), self._seed(), tuple(sorted(params.items())))


def uniform(rng: np.random.Generator, lo: float, hi: float, step: float = 0.005) -> float:
    """A seeded size in [lo, hi], rounded to ``step`` metres (round numbers, like real furniture)."""
    return float(np.round(rng.uniform(lo, hi) / step) * step)


# ----------------------------------------------------------------------------- carcass
@dataclass(frozen=True)
class Opening:
    """A rectangular front opening of a carcass: x in [x0, x1], z in [z0, z1] (m)."""

    x0: float
    x1: float
    z0: float
    z1: float

    @property
    def width(self) -> float:
        return self.x1 - self.x0

    @property
    def height(self) -> float:
        return self.z1 - self.z0


def carcass(lo, hi, wall: float, openings: list[Opening]) -> S.Solid:
    """A box spanning ``lo``..``hi`` with front (-y) cavities behind each opening, back wall ``wall`` thick."""
    cuts = [S.box_between((o.x0, lo[1] - 0.01, o.z0), (o.x1, hi[1] - wall, o.z1)) for o in openings]
    return S.subtract(S.box_between(lo, hi), cuts)


def grid_openings(x0: float, x1: float, z0: float, z1: float, wall: float, rows: list[float],
                  cols: int = 1) -> list[list[Opening]]:
    """Split the frame [x0, x1] x [z0, z1] into rows (relative heights ``rows``, bottom first) and
    ``cols`` columns separated by ``wall``-thick dividers; returns openings[row][col]."""
    inner_w = x1 - x0 - (cols + 1) * wall
    inner_h = z1 - z0 - (len(rows) + 1) * wall
    hs = np.asarray(rows, float) / np.sum(rows) * inner_h
    out, z = [], z0 + wall
    for h in hs:
        row, x = [], x0 + wall
        for _ in range(cols):
            w = inner_w / cols
            row.append(Opening(x, x + w, z, z + h))
            x += w + wall
        out.append(row)
        z += h + wall
    return out


# ----------------------------------------------------------------------------- handles
def bar_handle(center, along, outward, length: float, standoff: float = 0.03, radius: float = 0.006) -> S.Solid:
    """A bar handle: a rod of ``length`` along ``along``, held ``standoff`` out along ``outward`` by two posts."""
    c, a, o = (np.asarray(v, float) for v in (center, along, outward))
    ends = [c + a * length * 0.4, c - a * length * 0.4]
    posts = [S.rod(e - o * 0.002, e + o * standoff, radius * 0.8, 10) for e in ends]
    grip = S.rod(c + o * standoff - a * length / 2, c + o * standoff + a * length / 2, radius, 12)
    return S.union(posts + [grip])


def knob(center, outward, radius: float = 0.014, length: float = 0.025) -> S.Solid:
    """A round knob: stem and cap along ``outward`` from ``center``."""
    c, o = np.asarray(center, float), np.asarray(outward, float)
    stem = S.rod(c - o * 0.002, c + o * length * 0.6, radius * 0.45, 12)
    cap = S.cylinder(radius, length * 0.45, c + o * length * 0.75, o, 20)
    return S.union([stem, cap])


# ----------------------------------------------------------------------------- moving parts
def add_drawer(b: ObjectBuilder, parent: int, name: str, o: Opening, y_front: float, depth: float,
               overlay: float, front: Material, body: Material, handle_mat: Material, handle: str = "bar",
               travel_frac: float = 0.75, front_t: float = 0.018, wall: float = 0.008) -> int:
    """A drawer in opening ``o`` of a carcass whose front face is at y = ``y_front``; returns its part index.

    The drawer box sits in the cavity with ``GAP`` clearance; its front panel overlays the opening by
    ``overlay`` on every side, ``GAP`` in front of the carcass. Prismatic along -y, travel
    ``travel_frac`` of ``depth``.
    """
    p = b.part(name)
    box_lo = (o.x0 + GAP, y_front - GAP, o.z0 + GAP)
    box_hi = (o.x1 - GAP, y_front + depth, o.z1 - GAP - min(0.01, 0.15 * o.height))
    b.add(p, S.open_box(box_lo, box_hi, wall, "+z"), body)
    f_lo = (o.x0 - overlay, y_front - GAP - front_t, o.z0 - overlay)
    f_hi = (o.x1 + overlay, y_front - GAP, o.z1 + overlay)
    b.add(p, S.box_between(f_lo, f_hi), front)
    cx, cz = (o.x0 + o.x1) / 2, (o.z0 + o.z1) / 2 + (0.0 if o.height < 0.25 else 0.3 * o.height)
    face = (cx, f_lo[1], cz)
    if handle == "knob":
        b.add(p, knob(face, (0, -1, 0)), handle_mat)
    else:
        L = min(0.16, 0.45 * o.width)
        b.add(p, bar_handle(face, (1, 0, 0), (0, -1, 0), L, 0.025, 0.005), handle_mat)
    b.prismatic(f"{name}_slide", parent, p, (0, -1, 0), (0.0, round(travel_frac * depth, 4)))
    return p


def hinge_axis(lo, hi, outward: str, hinge_side: str) -> tuple[np.ndarray, np.ndarray]:
    """Axis and origin of a panel spanning ``lo``..``hi`` hinged on its ``hinge_side`` edge of its
    ``outward`` face, oriented so that a positive angle swings the free edge out along ``outward``.

    The axis runs along the panel's outer face edge, so every point of the panel stays on the outer
    side of its rest inner face while opening (no sweep into the carcass).
    """
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    n = np.asarray(_UNIT[outward], float)
    h = np.asarray(_UNIT[hinge_side], float)
    axis = np.cross(-h, n)
    origin = (lo + hi) / 2
    for k in range(3):
        if n[k]:
            origin[k] = hi[k] if n[k] > 0 else lo[k]
        if h[k]:
            origin[k] = hi[k] if h[k] > 0 else lo[k]
    return axis, origin


def add_door(b: ObjectBuilder, parent: int, name: str, o: Opening, y_front: float, overlay: float,
             hinge_side: str, panel: Material, handle_mat: Material, max_angle: float,
             thickness: float = 0.02, handle: str = "bar") -> int:
    """An overlay door over opening ``o`` (carcass front at ``y_front``), hinged on ``hinge_side``
    ("-x", "+x" vertical hinges; "-z" a drop-down door; "+z" a flap opening upward); returns its part index.

    ``handle``: "bar", "knob" or "none".
    """
    p = b.part(name)
    lo = np.array([o.x0 - overlay, y_front - GAP - thickness, o.z0 - overlay])
    hi = np.array([o.x1 + overlay, y_front - GAP, o.z1 + overlay])
    free = -np.asarray(_UNIT[hinge_side], float)
    # Opening, the free edge's back corner first swings *out* sideways by up to t²/(2w) (w = panel
    # width): trim the free edge by that much so a facing door (double doors) is never touched.
    k = int(np.argmax(np.abs(free)))
    trim = thickness**2 / (2 * (hi[k] - lo[k])) + 0.001
    if free[k] > 0:
        hi[k] -= trim
    else:
        lo[k] += trim
    b.add(p, S.box_between(lo, hi), panel)
    c = (lo + hi) / 2
    size = hi - lo
    grip = c.copy()
    grip[k] += free[k] * (size[k] / 2 - min(0.05, 0.2 * size[k]))
    grip[1] = lo[1]
    along = (0, 0, 1) if hinge_side in ("-x", "+x") else (1, 0, 0)
    span = size[2] if hinge_side in ("-x", "+x") else size[0]
    if handle == "knob":
        b.add(p, knob(grip, (0, -1, 0)), handle_mat)
    elif handle == "bar":
        b.add(p, bar_handle(grip, along, (0, -1, 0), min(0.3, 0.35 * span), 0.03, 0.006), handle_mat)
    axis, origin = hinge_axis(lo, hi, "-y", hinge_side)
    b.revolute(f"{name}_hinge", parent, p, axis, origin, (0.0, max_angle))
    return p
