"""Generators mirroring RS-Art's six real categories: drawer unit, desk lamp, eyeglasses,
floppy-disk drive, woven basket, phone/laptop stand.

Each ``make_<category>(b, rng, n_movable)`` fills an :class:`ObjectBuilder` with a seeded,
plausibly-sized instance (metres; z up; base on z = 0; front faces -y). ``n_movable`` is the
number of movable parts (None: chosen from the seed within the category's range).
"""
from __future__ import annotations

import numpy as np

from . import shapes as S
from .builder import ObjectBuilder
from .furniture import GAP, Opening, Palette, add_door, add_drawer, carcass, grid_openings, hinge_axis, uniform


def make_drawer(b: ObjectBuilder, rng: np.random.Generator, n_movable: int | None) -> None:
    """A desktop drawer unit with 1-3 stacked prismatic drawers."""
    n = n_movable or int(rng.integers(1, 4))
    pal = Palette(rng)
    W, D = uniform(rng, 0.24, 0.40), uniform(rng, 0.22, 0.34)
    heights = [uniform(rng, 0.07, 0.12) for _ in range(n)]
    wall = 0.012
    H = sum(heights) + (n + 1) * wall + 0.01
    wooden = rng.random() < 0.6
    body = pal.make("carcass", "wood" if wooden else "noise")
    front = pal.make("front", "wood" if not wooden or rng.random() < 0.5 else "noise")
    inner = pal.make("inner", "noise", (0.85, 0.82, 0.76))
    metal = pal.make("handle", "metal")
    base = b.part("base")
    feet_h = 0.01
    rows = grid_openings(-W / 2, W / 2, feet_h, H, wall, heights)
    b.add(base, carcass((-W / 2, -D / 2, feet_h), (W / 2, D / 2, H), wall, [r[0] for r in rows]), body)
    for sx in (-1, 1):
        for sy in (-1, 1):
            b.add(base, S.box((0.03, 0.03, feet_h + 0.001), (sx * (W / 2 - 0.025), sy * (D / 2 - 0.025), feet_h / 2 + 0.0005)), body)
    style = "knob" if rng.random() < 0.4 else "bar"
    for i, r in enumerate(rows):
        add_drawer(b, base, f"drawer_{i}", r[0], -D / 2, D - wall - 2 * GAP - 0.005, wall / 2 - GAP,
                   front, inner, metal, style)


def make_desk_lamp(b: ObjectBuilder, rng: np.random.Generator, n_movable: int | None) -> None:
    """An architect desk lamp: weighted base and post, then 2-3 chained revolute links (lower arm,
    upper arm, head), each hinged about x and offset sideways into its own slab so links never collide."""
    n = n_movable or int(rng.integers(2, 4))
    pal = Palette(rng)
    paint = pal.make("paint", "noise")
    metal = pal.make("metal", "metal")
    base_r, base_h = uniform(rng, 0.07, 0.10), uniform(rng, 0.018, 0.03)
    post_h = uniform(rng, 0.05, 0.09)
    L1, L2 = uniform(rng, 0.24, 0.34), uniform(rng, 0.22, 0.32)
    w = 0.014                                     # link bar width (x) and depth
    hub_r = 0.012
    base = b.part("base")
    b.add(base, S.cylinder(base_r, base_h, (0, 0, base_h / 2), segments=32), paint)
    b.add(base, S.cylinder(0.012, post_h, (0, 0, base_h + post_h / 2 - 0.001)), metal)
    post_top = base_h + post_h
    z0 = post_top + hub_r + GAP
    fork_t = 0.005
    for sx in (-1, 1):
        b.add(base, S.box_between((sx * (w / 2 + GAP) if sx > 0 else -(w / 2 + GAP + fork_t), -0.011, post_top - 0.006),
                                  (sx * (w / 2 + GAP + fork_t) if sx > 0 else -(w / 2 + GAP), 0.011, z0 + 0.008)), metal)
    b.add(base, S.box_between((-(w / 2 + GAP + fork_t), -0.011, post_top - 0.006), (w / 2 + GAP + fork_t, 0.011, post_top)), metal)

    # lower arm: tilted back (+y) by a1 from vertical
    a1 = rng.uniform(0.15, 0.35)
    d1 = np.array([0.0, np.sin(a1), np.cos(a1)])
    p0 = np.array([0.0, 0.0, z0])
    p1 = p0 + L1 * d1
    arm1 = b.part("arm_lower")
    b.add(arm1, S.cylinder(hub_r, w, p0, (1, 0, 0)), metal)
    b.add(arm1, S.bar(p0, p1, w, w, up=(1, 0, 0)), paint)
    b.add(arm1, S.cylinder(hub_r, w, p1, (1, 0, 0)), metal)
    b.revolute("shoulder", 0, arm1, (1, 0, 0), p0, (-0.3, 0.25))

    # upper arm: in the slab beside the lower arm, pointing forward (-y) and slightly up
    x2 = w + GAP
    a2 = rng.uniform(-0.15, 0.25)
    d2 = np.array([0.0, -np.cos(a2), np.sin(a2)])
    q1 = p1 + np.array([x2, 0, 0])
    q2 = q1 + L2 * d2
    arm2 = b.part("arm_upper")
    b.add(arm2, S.cylinder(hub_r, w, q1, (1, 0, 0)), metal)
    b.add(arm2, S.bar(q1, q2, w, w, up=(1, 0, 0)), paint)
    b.revolute("elbow", arm1, arm2, (-1, 0, 0), p1, (-0.35, 0.6))

    shade_r = uniform(rng, 0.045, 0.07)
    shade_h = uniform(rng, 0.08, 0.12)

    def add_head(part: int, wrist: np.ndarray) -> None:
        b.add(part, S.cylinder(hub_r * 0.9, w, wrist, (1, 0, 0)), metal)
        stem_end = wrist + np.array([0.0, -0.05, -0.01])
        b.add(part, S.bar(wrist, stem_end, w * 0.8, w * 0.8, up=(1, 0, 0)), metal)
        top = stem_end + np.array([0.0, -0.01, -0.005])
        shade = S.cylinder(0.018, shade_h, top + np.array([0, 0, -shade_h / 2]), (0, 0, 1), 28)
        cone = S.subtract(S.cylinder(shade_r, shade_h, top + np.array([0, 0, -shade_h / 2]), (0, 0, -1), 28,
                                     radius_top=0.02),
                          [S.cylinder(shade_r - 0.004, shade_h, top + np.array([0, 0, -shade_h / 2 - 0.004]),
                                      (0, 0, -1), 28, radius_top=0.016)])
        b.add(part, S.union([shade, cone]), paint)

    wrist = q2 + np.array([0.0, -hub_r - GAP - 0.002, 0.0])
    if n >= 3:
        b.add(arm2, S.cylinder(hub_r * 0.9, w, q2, (1, 0, 0)), metal)
        head = b.part("head")
        add_head(head, q2 + np.array([-(w + GAP), 0, 0]))
        b.revolute("wrist", arm2, head, (1, 0, 0), q2, (-0.6, 0.5))
    else:
        add_head(arm2, wrist)


def make_eyeglasses(b: ObjectBuilder, rng: np.random.Generator, n_movable: int | None, style: str = "rs") -> None:
    """Eyeglasses standing on their rims and temple tips: a front frame and two revolute temples.

    The right temple's hinge axis is vertical; the left one's is tilted back so that, folding, it rises
    over the right temple (as real temples stack) instead of passing through it.
    """
    pal = Palette(rng)
    tortoise = style == "rs" and rng.random() < 0.6
    frame_m = pal.make("frame", "noise", (0.35, 0.22, 0.12) if tortoise else pal.pick([(0.1, 0.1, 0.1), (0.2, 0.25, 0.4), (0.5, 0.1, 0.1)]))
    if style != "rs":
        frame_m = pal.make("frame", "metal")
    lens_m = pal.make("lens", "glass", (0.75, 0.82, 0.88))
    temple_m = frame_m
    lw, lh = uniform(rng, 0.024, 0.030, 0.001), uniform(rng, 0.016, 0.022, 0.001)   # lens half-axes
    rim = uniform(rng, 0.003, 0.005, 0.001)
    bridge = uniform(rng, 0.008, 0.012, 0.001)
    depth = 0.004                                                                     # frame thickness (y)
    cx = bridge / 2 + rim + lw
    zc = lh + rim
    y0 = -0.075
    base = b.part("frame")
    T_front = lambda x, z: np.array([[1, 0, 0, x], [0, 0, -1, y0 + depth / 2], [0, 1, 0, z], [0, 0, 0, 1]], float)
    round_lens = style != "rs" and rng.random() < 0.5
    for sx in (-1, 1):
        outer = S.ellipse(lw + rim, lh + rim, 40) if not round_lens else S.rounded_rect(2 * (lw + rim), 2 * (lh + rim), 0.008)
        inner = S.ellipse(lw, lh, 40) if not round_lens else S.rounded_rect(2 * lw, 2 * lh, 0.006)
        b.add(base, S.extrude(outer, depth, T_front(sx * cx, zc) @ _tz(-depth / 2), holes=[inner]), frame_m)
        b.add(base, S.extrude(inner * 1.02, 0.0015, T_front(sx * cx, zc) @ _tz(-0.00075)), lens_m)
    b.add(base, S.bar((-cx + lw * 0.8, y0 + depth / 2, zc + lh * 0.55), (cx - lw * 0.8, y0 + depth / 2, zc + lh * 0.55),
                      depth, 0.003, up=(0, 0, 1)), frame_m)
    # end pieces: from the rim's outer edge back to the hinge
    xe = cx + lw + rim                       # outer x of the rims
    tw, th = 0.003, 0.005                    # temple width (x), height (z)
    zh = zc + lh * 0.45
    yh = y0 + depth + tw / 2 + GAP + 0.001   # hinge axis y (behind the frame's back face)
    xh = xe - tw / 2
    bend = 0.015                             # horizontal run of the ear bend
    for sx in (-1, 1):
        b.add(base, S.box_between((sx * (xe - 0.004) if sx > 0 else -xe - 0.004, y0, zh - th / 2),
                                  (xe + 0.004 if sx > 0 else -(xe - 0.004), yh + 0.004, zh + th / 2)), frame_m)
    for side, sx in (("right", 1), ("left", -1)):
        p = b.part(f"temple_{side}")
        hx = sx * (xh - 0.004 - GAP - tw / 2)
        start = np.array([hx, yh + tw / 2 + GAP, zh])
        L = 2 * abs(hx) - bend - 0.012      # folded, the tip stops short of the other hinge
        end = np.array([hx, yh + L, zh])
        b.add(p, S.bar(start, end, tw, th), temple_m)
        tip = end + np.array([0.0, bend, -(zh - 0.004)])
        b.add(p, S.bar(end - np.array([0, 0.002, 0]), tip, tw, th, up=(0, 1, 0.5)), temple_m)
        tilt = 0.0 if side == "right" else 0.6
        axis = np.array([0.0, np.sin(tilt), np.cos(tilt)]) * (1 if sx > 0 else -1)
        b.revolute(f"temple_{side}_hinge", base, p, axis, (hx, yh, zh), (0.0, round(np.pi / 2 - 0.05, 4)))


def _tz(dz: float) -> np.ndarray:
    T = np.eye(4)
    T[2, 3] = dz
    return T


def make_floppy_drive(b: ObjectBuilder, rng: np.random.Generator, n_movable: int | None) -> None:
    """An external floppy-disk drive: a disk tray sliding out of a front slot (prismatic) and a
    dust flap over the front bay, hinged at its top edge (revolute)."""
    pal = Palette(rng)
    shell = pal.make("shell", "noise", pal.pick([(0.85, 0.84, 0.80), (0.22, 0.22, 0.24), (0.75, 0.74, 0.70)]))
    disk = pal.make("disk", "print", pal.pick([(0.15, 0.15, 0.18), (0.2, 0.3, 0.6), (0.6, 0.15, 0.15)]),
                    accent=(0.95, 0.95, 0.92), accent2=(0.7, 0.7, 0.72), cells=3)
    tray_m = pal.make("tray", "noise", (0.3, 0.3, 0.32))
    W, D, H = uniform(rng, 0.13, 0.16), uniform(rng, 0.17, 0.21), uniform(rng, 0.045, 0.06)
    wall = 0.004
    base = b.part("base")
    slot = Opening(-0.05, 0.05, 0.008, 0.008 + 0.012)
    bay = Opening(-W / 2 + 0.012, W / 2 - 0.012, slot.z1 + 0.006, H - 0.008)
    b.add(base, carcass((-W / 2, -D / 2, 0.0), (W / 2, D / 2, H), wall, [slot]), shell)
    b.add(base, S.box_between((bay.x0 + 0.01, -D / 2 - 0.0005, bay.z0 + 0.004), (bay.x1 - 0.01, -D / 2 + 0.001, bay.z1 - 0.004)), tray_m)
    tray = b.part("tray")
    t_lo = (slot.x0 + GAP, -D / 2 - 0.006, slot.z0 + GAP)
    t_hi = (slot.x1 - GAP, D / 2 - wall - GAP - 0.02, slot.z0 + GAP + 0.004)
    b.add(tray, S.box_between(t_lo, t_hi), tray_m)
    b.add(tray, S.box_between((slot.x0 + GAP, -D / 2 - 0.010, slot.z0 + GAP), (slot.x1 - GAP, -D / 2 - 0.006, slot.z1 - GAP)), tray_m)
    b.add(tray, S.box_between((-0.045, -D / 2 + 0.002, t_hi[2] - 0.001), (0.045, -D / 2 + 0.095, t_hi[2] + 0.0033)), disk)
    b.prismatic("tray_slide", 0, tray, (0, -1, 0), (0.0, round(uniform(rng, 0.07, 0.09), 4)))
    flap = add_door(b, 0, "flap", bay, -D / 2, 0.0, "+z", shell, tray_m, round(rng.uniform(1.2, 1.6), 3),
                    thickness=0.003, handle="none")
    # a finger lip along the flap's free (bottom) edge
    b.add(flap, S.box_between((bay.x0 + 0.02, -D / 2 - GAP - 0.006, bay.z0), (bay.x1 - 0.02, -D / 2 - GAP - 0.002, bay.z0 + 0.003)), tray_m)


def make_woven_basket(b: ObjectBuilder, rng: np.random.Generator, n_movable: int | None) -> None:
    """A tapered woven basket (basket-weave texture) with 1-2 revolute lids or a carrying handle."""
    n = n_movable or int(rng.integers(1, 3))
    pal = Palette(rng)
    weave = pal.make("weave", "weave", pal.pick([(0.80, 0.64, 0.40), (0.66, 0.50, 0.30), (0.86, 0.76, 0.56)]),
                     blocks=int(rng.integers(8, 14)))
    rim_m = pal.make("rim", "wood")
    W, D, H = uniform(rng, 0.30, 0.42), uniform(rng, 0.22, 0.30), uniform(rng, 0.14, 0.22)
    taper = rng.uniform(0.82, 0.9)
    wall = 0.008
    base = b.part("base")
    outer = S.extrude(S.rounded_rect(W * taper, D * taper, 0.03), H, scale_top=(1 / taper, 1 / taper))
    inner = S.extrude(S.rounded_rect(W * taper - 2 * wall, D * taper - 2 * wall, 0.025), H,
                      _tz(wall), scale_top=(1 / taper, 1 / taper))
    b.add(base, S.subtract(outer, [inner]), weave)
    rim = S.subtract(S.extrude(S.rounded_rect(W + 0.008, D + 0.008, 0.034), 0.012, _tz(H - 0.012)),
                     [S.extrude(S.rounded_rect(W - 2 * wall, D - 2 * wall, 0.026), 0.02, _tz(H - 0.016))])
    b.add(base, rim, rim_m)
    lid_t = 0.01
    kind = "handle" if (n == 1 and rng.random() < 0.5) else "lids"
    if kind == "handle":
        zp = H + 0.012                                   # pivot above the rim: the arc clears it when tilted
        x_hub = W / 2 + 0.012                            # outer face of the base's pivot hubs
        R = x_hub + GAP + 0.009                          # arc radius = centre of the handle's foot discs
        for sx in (-1, 1):
            b.add(base, S.cylinder(0.012, 0.016, (sx * (x_hub - 0.008), 0, zp), (1, 0, 0)), rim_m)
            b.add(base, S.box_between((sx * (W / 2 - 0.004) if sx > 0 else -x_hub, -0.01, H - 0.03),
                                      (x_hub if sx > 0 else -(W / 2 - 0.004), 0.01, zp)), rim_m)
        h = b.part("handle")
        arc = S.torus(R, 0.007, (0, 0, zp), degrees=180, segments=32, plane=((1, 0, 0), (0, 0, 1)))
        discs = [S.cylinder(0.012, 0.016, (sx * R, 0, zp), (1, 0, 0)) for sx in (-1, 1)]
        b.add(h, S.union([arc] + discs), weave)
        lim = round(float(rng.uniform(0.9, 1.2)), 3)
        b.revolute("handle_pivot", 0, h, (1, 0, 0), (0, 0, zp), (-lim, lim))
        return
    z_lid = H + GAP
    if n == 1:
        lo, hi = (-W / 2 - 0.002, -D / 2 - 0.002, z_lid), (W / 2 + 0.002, D / 2 + 0.002, z_lid + lid_t)
        lid = b.part("lid")
        b.add(lid, S.box_between(lo, hi), weave)
        b.add(lid, S.bar((-0.04, -D / 2 + 0.03, hi[2] - 0.001), (0.04, -D / 2 + 0.03, hi[2] - 0.001), 0.012, 0.012), rim_m)
        axis, origin = hinge_axis(lo, hi, "+z", "+y")
        b.revolute("lid_hinge", 0, lid, axis, origin, (0.0, round(rng.uniform(1.6, 1.85), 3)))
    else:
        b.add(base, S.box((0.02, D + 0.008, 0.012), (0, 0, H + 0.006 - 0.0005)), rim_m)     # centre rail
        for side, sx in (("left", -1), ("right", 1)):
            lo = np.array([0.01 + GAP if sx > 0 else -W / 2 - 0.002, -D / 2 - 0.002, H + 0.012 + GAP])
            hi = np.array([W / 2 + 0.002 if sx > 0 else -0.01 - GAP, D / 2 + 0.002, H + 0.012 + GAP + lid_t])
            if sx < 0:
                lo[0], hi[0] = -W / 2 - 0.002, -0.01 - GAP
            lid = b.part(f"lid_{side}")
            b.add(lid, S.box_between(lo, hi), weave)
            axis, origin = hinge_axis(lo, hi, "+z", "-x" if sx > 0 else "+x")
            b.revolute(f"lid_{side}_hinge", 0, lid, axis, origin, (0.0, round(rng.uniform(1.2, 1.45), 3)))  # hinged at the centre: stop short of vertical


def make_stand(b: ObjectBuilder, rng: np.random.Generator, n_movable: int | None) -> None:
    """A folding phone/laptop stand: base plate, support arm hinged at the back of the base, and a
    holder plate with a lip hinged at the arm's front end (two chained revolute hinges).
    At rest everything is folded flat with clearances; opening lifts the arm and swings the holder up."""
    pal = Palette(rng)
    alu = pal.make("alu", "metal", pal.pick([(0.78, 0.79, 0.80), (0.35, 0.35, 0.37), (0.80, 0.70, 0.62)]))
    pad = pal.make("pad", "noise", (0.15, 0.15, 0.15))
    W = uniform(rng, 0.08, 0.26)
    D = uniform(rng, 0.14, 0.22)
    t = 0.005
    knuckle = 0.007
    base = b.part("base")
    b.add(base, S.box_between((-W / 2, -D / 2, 0), (W / 2, D / 2, t)), alu)
    b.add(base, S.box_between((-W / 2 + 0.01, -D / 2 + 0.01, t - 0.001), (W / 2 - 0.01, -D / 2 + 0.03, t + 0.002)), pad)
    # base knuckles at the back corners; the arm's knuckle sits between them
    za = t + GAP + t / 2 + 0.004                     # arm hinge axis height
    ya = D / 2 - knuckle
    for sx in (-1, 1):
        b.add(base, S.box_between((sx * W / 2 - (0.012 if sx > 0 else 0), ya - knuckle, 0),
                                  (sx * W / 2 + (0.012 if sx < 0 else 0), ya + knuckle, za + knuckle)), alu)
        b.add(base, S.cylinder(knuckle, 0.012, (sx * (W / 2 - 0.006), ya, za + 0.0), (1, 0, 0)), alu)
    arm = b.part("arm")
    wa = W - 2 * 0.012 - 2 * GAP
    arm_lo = np.array([-wa / 2, -D / 2 + 0.02, za - t / 2])
    arm_hi = np.array([wa / 2, ya, za + t / 2])
    b.add(arm, S.box_between(arm_lo, arm_hi), alu)
    b.add(arm, S.cylinder(t / 2 + 0.0015, wa, (0, ya, za), (1, 0, 0)), alu)
    b.revolute("arm_hinge", 0, arm, (-1, 0, 0), (0, ya, za), (0.0, round(rng.uniform(0.9, 1.2), 3)))
    # holder hinge at the arm's front end, holder folded back on top of the arm
    yh = arm_lo[1] + 0.004
    zh = za + t / 2 + GAP + t / 2
    holder = b.part("holder")
    wh = wa - 0.01
    b.add(holder, S.box_between((-wh / 2, yh, zh - t / 2), (wh / 2, ya - 0.03, zh + t / 2)), alu)
    b.add(holder, S.box_between((-wh / 2, ya - 0.03 - t, zh - t / 2), (wh / 2, ya - 0.03, zh + t / 2 + 0.012)), alu)
    b.add(holder, S.box_between((-wh / 2 + 0.01, yh + 0.01, zh + t / 2 - 0.001), (wh / 2 - 0.01, ya - 0.05, zh + t / 2 + 0.0015)), pad)
    b.revolute("holder_hinge", arm, holder, (1, 0, 0), (0, yh, zh), (0.0, round(rng.uniform(1.9, 2.3), 3)))
