"""Generators mirroring the eight PartNet-Mobility categories of the paper's evaluation: box, door,
(eyeglasses: shared with rs_art_like), faucet, oven, refrigerator, storage furniture, table.

Same conventions as :mod:`rs_art_like`: metres, z up, base on z = 0, front faces -y; ``n_movable``
is the number of movable parts (the registry passes 2 by default, 3 or 5 for the multi-part sets).
"""
from __future__ import annotations

import numpy as np

from . import shapes as S
from .builder import ObjectBuilder
from .furniture import GAP, Opening, Palette, add_door, add_drawer, carcass, grid_openings, hinge_axis, uniform


def make_box(b: ObjectBuilder, rng: np.random.Generator, n_movable: int | None) -> None:
    """A printed storage box: open-top shell with 1 lid or 2 side lid flaps (+ a drop-down front flap for 3)."""
    n = n_movable or 2
    pal = Palette(rng)
    card = pal.make("card", "print", pal.pick([(0.78, 0.64, 0.45), (0.92, 0.92, 0.88), (0.35, 0.45, 0.6)]),
                    accent=pal.pick([(0.1, 0.2, 0.6), (0.7, 0.1, 0.1), (0.1, 0.4, 0.2)]), cells=int(rng.integers(3, 7)))
    W, D, H = uniform(rng, 0.25, 0.45), uniform(rng, 0.2, 0.35), uniform(rng, 0.12, 0.28)
    wall, t = 0.006, 0.006
    base = b.part("base")
    b.add(base, S.open_box((-W / 2, -D / 2, 0), (W / 2, D / 2, H), wall, "+z"), card)
    z0 = H + GAP
    if n == 1:
        lo, hi = np.array([-W / 2, -D / 2, z0]), np.array([W / 2, D / 2, z0 + t])
        p = b.part("lid")
        b.add(p, S.box_between(lo, hi), card)
        axis, origin = hinge_axis(lo, hi, "+z", "+y")
        b.revolute("lid_hinge", 0, p, axis, origin, (0.0, round(rng.uniform(1.7, 2.0), 3)))
        return
    # two side flaps meeting in the middle; a third (back) flap lies on top of them
    for side, sx in (("left", -1), ("right", 1)):
        lo = np.array([-W / 2 if sx < 0 else GAP, -D / 2, z0])
        hi = np.array([-GAP if sx < 0 else W / 2, D / 2, z0 + t])
        p = b.part(f"lid_{side}")
        b.add(p, S.box_between(lo, hi), card)
        axis, origin = hinge_axis(lo, hi, "+z", "-x" if sx < 0 else "+x")
        b.revolute(f"lid_{side}_hinge", 0, p, axis, origin, (0.0, round(rng.uniform(1.6, 2.2), 3)))
    if n >= 3:   # a drop-down front flap over a window cut in the front wall
        win = Opening(-W / 2 + 0.03, W / 2 - 0.03, 0.03, 0.03 + 0.55 * (H - 0.03))
        b.parts[base].pieces[0] = (S.subtract(b.parts[base].pieces[0][0], [S.box_between(
            (win.x0, -D / 2 - 0.01, win.z0), (win.x1, -D / 2 + wall + 0.01, win.z1))]), card)
        add_door(b, base, "flap_front", win, -D / 2, 0.01, "-z", card, card, round(rng.uniform(1.4, 1.57), 3),
                 thickness=t, handle="none")


def make_door(b: ObjectBuilder, rng: np.random.Generator, n_movable: int | None) -> None:
    """A door in its frame (on a floor plate): the leaf on a vertical hinge, a lever handle on the leaf."""
    pal = Palette(rng)
    leaf_m = pal.make("leaf", "wood" if rng.random() < 0.6 else "noise")
    frame_m = pal.make("frame", "wood")
    metal = pal.make("handle", "metal")
    Wd, Hd = uniform(rng, 0.70, 0.90), uniform(rng, 1.95, 2.10)
    jamb, t = 0.06, uniform(rng, 0.035, 0.045)
    depth = 0.12
    plate = 0.02
    base = b.part("frame")
    b.add(base, S.box_between((-Wd / 2 - jamb - 0.1, -0.3, 0), (Wd / 2 + jamb + 0.1, 0.3, plate)), frame_m)
    for sx in (-1, 1):
        x0 = Wd / 2 if sx > 0 else -Wd / 2 - jamb
        b.add(base, S.box_between((x0, -depth / 2, plate - 0.001), (x0 + jamb, depth / 2, plate + Hd + jamb)), frame_m)
    b.add(base, S.box_between((-Wd / 2 - 0.001, -depth / 2, plate + Hd), (Wd / 2 + 0.001, depth / 2, plate + Hd + jamb)), frame_m)
    hinge_left = rng.random() < 0.5
    leaf = b.part("door_leaf")
    lo = np.array([-Wd / 2 + GAP, -t / 2, plate + GAP + 0.005])
    hi = np.array([Wd / 2 - GAP, t / 2, plate + Hd - GAP])
    panel = S.box_between(lo, hi)
    # raised panels on the front face (a panelled door), part of the leaf
    insets = []
    for (z0, z1) in ((0.12, 0.45), (0.55, 0.92)):
        insets.append(S.box_between((lo[0] + 0.1, lo[1] - 0.004, lo[2] + z0 * (hi[2] - lo[2])),
                                    (hi[0] - 0.1, lo[1] + 0.001, lo[2] + z1 * (hi[2] - lo[2]))))
    b.add(leaf, S.union([panel] + insets), leaf_m)
    front_y = lo[1] - 0.004
    hs = "-x" if hinge_left else "+x"
    axis, origin = hinge_axis((lo[0], front_y, lo[2]), hi, "-y", hs)
    b.revolute("door_hinge", 0, leaf, axis, origin, (0.0, round(rng.uniform(1.3, 1.7), 3)))
    # lever handle near the free edge at 1.0 m
    fx = (hi[0] - 0.07) if hinge_left else (lo[0] + 0.07)
    hz = plate + uniform(rng, 0.95, 1.05)
    b.add(leaf, S.cylinder(0.028, 0.008, (fx, front_y - 0.004 + 0.001, hz), (0, 1, 0)), metal)   # rose (fixed)
    handle = b.part("handle")
    hub_y = front_y - 0.008 - GAP
    lever_dir = 1.0 if not hinge_left else -1.0          # lever points toward the hinge side
    b.add(handle, S.cylinder(0.012, 0.03, (fx, hub_y - 0.015, hz), (0, 1, 0)), metal)
    Lh = uniform(rng, 0.11, 0.14)
    b.add(handle, S.rod((fx, hub_y - 0.026, hz), (fx + lever_dir * Lh, hub_y - 0.026, hz), 0.009, 12), metal)
    b.revolute("handle_turn", leaf, handle, (0, lever_dir, 0), (fx, hub_y, hz), (0.0, round(rng.uniform(0.6, 0.8), 3)))


def make_faucet(b: ObjectBuilder, rng: np.random.Generator, n_movable: int | None) -> None:
    """A basin faucet on a deck plate: two cross/lever handles turning about horizontal axes, and
    (for 3 movable parts) a swivel gooseneck spout about the vertical axis."""
    n = n_movable or 2
    pal = Palette(rng)
    chrome = pal.make("chrome", "metal", pal.pick([(0.80, 0.81, 0.83), (0.72, 0.62, 0.40), (0.25, 0.25, 0.27)]))
    accent = pal.make("caps", "print", (0.9, 0.9, 0.9), accent=(0.8, 0.1, 0.1), accent2=(0.1, 0.2, 0.8), cells=2)
    R = uniform(rng, 0.022, 0.03)
    Hb = uniform(rng, 0.10, 0.16)
    base = b.part("base")
    b.add(base, S.box_between((-0.11, -0.045, 0), (0.11, 0.045, 0.012)), chrome)
    b.add(base, S.cylinder(R, Hb, (0, 0, Hb / 2 + 0.011)), chrome)
    hx = uniform(rng, 0.07, 0.085)
    for sx in (-1, 1):
        b.add(base, S.cylinder(0.013, 0.03, (sx * hx, 0, 0.011 + 0.015), (0, 0, 1)), chrome)   # handle bodies
    for i, (side, sx) in enumerate((("left", -1), ("right", 1))):
        p = b.part(f"handle_{side}")
        top = np.array([sx * hx, 0, 0.011 + 0.03 + GAP])
        b.add(p, S.cylinder(0.011, 0.012, top + (0, 0, 0.006)), chrome)
        arm = uniform(rng, 0.035, 0.05)
        b.add(p, S.bar(top + (0, 0, 0.012), top + (0, -arm, 0.02), 0.012, 0.008), chrome)
        b.add(p, S.cylinder(0.008, 0.004, top + (0, 0, 0.0145), (0, 0, 1)), accent)
        b.revolute(f"handle_{side}_turn", 0, p, (0, 0, sx), top, (0.0, round(rng.uniform(1.2, 1.57), 3)))
    reach = uniform(rng, 0.10, 0.15)
    rise = uniform(rng, 0.06, 0.12)
    r_tube = 0.011
    top_z = Hb + 0.011
    if n >= 3:
        spout = b.part("spout")
        z = top_z + GAP
    else:
        spout, z = 0, top_z - 0.002
    bend = reach / 2
    col = S.cylinder(r_tube, rise, (0, 0, z + rise / 2))
    arc = S.torus(bend, r_tube, (0, -bend, z + rise), degrees=180, segments=24, plane=((0, 1, 0), (0, 0, 1)))
    nozzle = S.cylinder(r_tube * 1.1, 0.03, (0, -2 * bend, z + rise - 0.015))
    collar = S.cylinder(R * 0.9, 0.02, (0, 0, z + 0.01))
    b.add(spout, S.union([collar, col, arc, nozzle]), chrome)
    if n >= 3:
        b.revolute("spout_swivel", 0, spout, (0, 0, 1), (0, 0, z), (round(-0.9, 3), round(0.9, 3)))


def make_oven(b: ObjectBuilder, rng: np.random.Generator, n_movable: int | None) -> None:
    """A free-standing oven: hollow cavity behind a drop-down door (revolute about x at its bottom edge)
    and 1-2 rotary knobs on the control panel (revolute about y)."""
    n = n_movable or 2
    pal = Palette(rng)
    enamel = pal.make("enamel", "noise", pal.pick([(0.92, 0.92, 0.90), (0.22, 0.22, 0.24), (0.70, 0.70, 0.72)]))
    door_m = pal.make("door", "print", (0.18, 0.18, 0.2), accent=(0.05, 0.05, 0.07), accent2=(0.3, 0.3, 0.32), cells=1)
    metal = pal.make("metal", "metal")
    W, D, H = uniform(rng, 0.55, 0.65), uniform(rng, 0.55, 0.65), uniform(rng, 0.82, 0.92)
    wall = 0.03
    plinth = 0.08
    panel_h = 0.12
    base = b.part("body")
    door_open = Opening(-W / 2 + wall, W / 2 - wall, plinth + wall, H - panel_h - wall)
    b.add(base, carcass((-W / 2, -D / 2, 0), (W / 2, D / 2, H), wall, [door_open]), enamel)
    b.add(base, S.box_between((-W / 2 + 0.04, -0.15, H - 0.001), (W / 2 - 0.04, 0.2, H + 0.006)), metal)  # hob plate
    add_door(b, 0, "door", door_open, -D / 2, wall / 2 - GAP, "-z", door_m, metal, round(rng.uniform(1.45, 1.57), 3),
             thickness=0.03)
    kz = H - panel_h / 2
    xs = [-W / 2 + 0.1 + k * (W - 0.2) / max(1, n - 2) for k in range(n - 1)] if n > 2 else [uniform(rng, -0.15, 0.15)]
    for k, x in enumerate(xs):
        p = b.part(f"knob_{k}")
        c = np.array([x, -D / 2 - GAP, kz])
        b.add(p, S.cylinder(0.022, 0.02, c + (0, -0.01, 0), (0, 1, 0), 24), metal)
        b.add(p, S.box((0.008, 0.012, 0.036), c + (0, -0.026, 0.0)), metal)
        b.revolute(f"knob_{k}_turn", 0, p, (0, -1, 0), c, (0.0, round(rng.uniform(3.5, 4.7), 3)))


def make_refrigerator(b: ObjectBuilder, rng: np.random.Generator, n_movable: int | None) -> None:
    """A refrigerator with two doors: side-by-side (outer vertical hinges) or top/bottom doors hung
    on one co-axial hinge line (the co-axial case)."""
    pal = Palette(rng)
    skin = pal.make("skin", "metal" if rng.random() < 0.5 else "noise", pal.pick([(0.85, 0.86, 0.87), (0.93, 0.93, 0.92), (0.3, 0.3, 0.32)]))
    inner = pal.make("liner", "noise", (0.95, 0.95, 0.96))
    metal = pal.make("handle", "metal")
    W, D, H = uniform(rng, 0.6, 0.9), uniform(rng, 0.6, 0.72), uniform(rng, 1.6, 1.85)
    wall = 0.04
    coaxial = rng.random() < 0.5
    base = b.part("body")
    foot = 0.03
    if coaxial:
        split = uniform(rng, 0.32, 0.4)
        rows = grid_openings(-W / 2, W / 2, foot, H, wall, [1 - split, split])
        openings = [rows[0][0], rows[1][0]]
    else:
        cols = grid_openings(-W / 2, W / 2, foot, H, wall, [1.0], cols=2)
        openings = cols[0]
    b.add(base, carcass((-W / 2, -D / 2, 0), (W / 2, D / 2, H), wall, openings), skin)
    for o in openings:          # a shelf in each compartment
        b.add(base, S.box_between((o.x0 - 0.001, -D / 2 + 0.08, (o.z0 + o.z1) / 2), (o.x1 + 0.001, D / 2 - wall + 0.001,
                                                                                    (o.z0 + o.z1) / 2 + 0.008)), inner)
    ov = wall / 2 - GAP
    if coaxial:
        hs = "-x" if rng.random() < 0.5 else "+x"
        add_door(b, 0, "door_bottom", openings[0], -D / 2, ov, hs, skin, metal, round(rng.uniform(1.5, 1.9), 3), 0.05)
        add_door(b, 0, "door_top", openings[1], -D / 2, ov, hs, skin, metal, round(rng.uniform(1.5, 1.9), 3), 0.05)
    else:
        add_door(b, 0, "door_left", openings[0], -D / 2, ov, "-x", skin, metal, round(rng.uniform(1.5, 1.9), 3), 0.05)
        add_door(b, 0, "door_right", openings[1], -D / 2, ov, "+x", skin, metal, round(rng.uniform(1.5, 1.9), 3), 0.05)


def _cabinet(b: ObjectBuilder, rng, pal, x0, x1, z0, z1, D, n_drawers, n_doors, body, front, metal,
             base_part: int = 0, prefix: str = "", y_back: float | None = None) -> None:
    """Fill carcass box [x0, x1] x [-D/2, D/2] x [z0, z1] with drawers (top rows) over a door compartment."""
    wall = 0.018
    rows = []
    if n_doors:
        rows.append(("doors", uniform(rng, 2.0, 3.0, 0.1)))
    rows += [("drawer", 1.0)] * n_drawers
    grid = grid_openings(x0, x1, z0, z1, wall, [r[1] for r in rows])
    openings = []
    door_row = None
    for (kind, _), g in zip(rows, grid):
        if kind == "doors":
            door_row = g[0]
            if n_doors == 2:
                half = (g[0].x0 + g[0].x1) / 2
                openings += [Opening(g[0].x0, half - wall / 2, g[0].z0, g[0].z1), Opening(half + wall / 2, g[0].x1, g[0].z0, g[0].z1)]
            else:
                openings.append(g[0])
        else:
            openings.append(g[0])
    b.add(base_part, carcass((x0, -D / 2, z0), (x1, D / 2, z1), wall, openings), body)
    ov = wall / 2 - GAP
    k = 0
    if door_row is not None:
        if n_doors == 2:
            add_door(b, base_part, f"{prefix}door_left", openings[0], -D / 2, ov, "-x", front, metal, round(rng.uniform(1.4, 1.9), 3))
            add_door(b, base_part, f"{prefix}door_right", openings[1], -D / 2, ov, "+x", front, metal, round(rng.uniform(1.4, 1.9), 3))
            k = 2
        else:
            add_door(b, base_part, f"{prefix}door", openings[0], -D / 2, ov, "-x" if rng.random() < 0.5 else "+x", front,
                     metal, round(rng.uniform(1.4, 1.9), 3))
            k = 1
    for i, o in enumerate(openings[k:]):
        add_drawer(b, base_part, f"{prefix}drawer_{i}", o, -D / 2, D - wall - 2 * GAP - 0.005, ov, front, body, metal,
                   "bar" if o.width > 0.25 else "knob")


def make_storage(b: ObjectBuilder, rng: np.random.Generator, n_movable: int | None) -> None:
    """Storage furniture: a cabinet with doors below and drawers above (mixed joint types).
    2 movable: door + drawer or 2 doors or 2 drawers; 3: 2 doors + drawer or door + 2 drawers; 5: 2 doors + 3 drawers."""
    n = n_movable or 2
    pal = Palette(rng)
    wooden = rng.random() < 0.6
    body = pal.make("body", "wood" if wooden else "noise")
    front = pal.make("front", "wood" if wooden and rng.random() < 0.5 else "noise")
    metal = pal.make("handle", "metal")
    combos = {2: [(1, 1), (0, 2), (2, 0)], 3: [(1, 2), (2, 1)], 4: [(2, 2)], 5: [(3, 2)]}[n]
    n_drawers, n_doors = combos[int(rng.integers(len(combos)))]
    W, D = uniform(rng, 0.5, 0.9), uniform(rng, 0.35, 0.5)
    H = uniform(rng, 0.6, 0.9) + 0.12 * n_drawers
    base = b.part("body")
    plinth = 0.06
    b.add(base, S.box_between((-W / 2 + 0.02, -D / 2 + 0.03, 0), (W / 2 - 0.02, D / 2 - 0.02, plinth + 0.001)), body)
    _cabinet(b, rng, pal, -W / 2, W / 2, plinth, H, D, n_drawers, n_doors, body, front, metal, base)


def make_table(b: ObjectBuilder, rng: np.random.Generator, n_movable: int | None) -> None:
    """A desk: top on legs with a drawer pedestal and/or a door cupboard underneath.
    2 movable: drawer + door or 2 drawers; 3: 2 drawers + door; 5: 4 drawers + door."""
    n = n_movable or 2
    pal = Palette(rng)
    top_m = pal.make("top", "wood")
    body = pal.make("body", "wood" if rng.random() < 0.5 else "noise")
    front = pal.make("front", "wood")
    metal = pal.make("handle", "metal")
    W, D = uniform(rng, 1.0, 1.5), uniform(rng, 0.55, 0.75)
    H = uniform(rng, 0.72, 0.78)
    top_t = 0.03
    base = b.part("top")
    b.add(base, S.box_between((-W / 2, -D / 2, H - top_t), (W / 2, D / 2, H)), top_m)
    ped_w = uniform(rng, 0.38, 0.45)
    under = H - top_t
    pd = D - 0.06
    n_drawers, n_doors = {2: [(1, 1), (2, 0)], 3: [(2, 1)], 4: [(3, 1)], 5: [(4, 1)]}[n][int(rng.integers(1 if n > 2 else 2))]
    # left pedestal: drawers; right: door cupboard (or legs)
    _cabinet(b, rng, pal, -W / 2 + 0.01, -W / 2 + 0.01 + ped_w, 0.0, under - 0.001, pd, n_drawers, 0, body, front, metal, base,
             prefix="")
    if n_doors:
        _cabinet(b, rng, pal, W / 2 - 0.01 - ped_w, W / 2 - 0.01, 0.0, under - 0.001, pd, 0, n_doors, body, front, metal, base,
                 prefix="right_")
    else:
        for sy in (-1, 1):
            b.add(base, S.box_between((W / 2 - 0.06, sy * (D / 2 - 0.03) - 0.025, 0), (W / 2 - 0.01, sy * (D / 2 - 0.03) + 0.025, under + 0.001)), body)
    b.add(base, S.box_between((-W / 2 + ped_w, D / 2 - 0.05, under - 0.25), (W / 2 - 0.06, D / 2 - 0.03, under + 0.001)), body)  # modesty panel
