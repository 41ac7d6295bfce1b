"""Numba CPU kernels for tile binning and 3DGS compositing with a hand-written backward pass.

Hand-written (not PyTorch) because a per-pixel loop with early ray termination touches only the
entries each pixel really visits, which vectorised PyTorch cannot do without padding.

Every kernel is generic over float32/float64 (numba specialises per dtype); all constants are
passed in as typed scalars of the same dtype so float32 runs never silently promote to float64.
Work is parallel over tiles; per-Gaussian gradients are first written per (tile, Gaussian) list
entry and then summed serially, so results are deterministic and race-free.

Feature layout: F = 4 channels per Gaussian (r, g, b, camera depth z).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

TILE = 16


@njit(cache=True)
def tighten_rects(xmin, xmax, ymin, ymax, means2d, conics, opac, amin):
    """Shrink each 3DGS tile rectangle to the tiles the alpha >= amin ellipse
    d^T conic d <= -2 log(amin / o) can reach (plus 1 px for rounding). Exact: the dropped
    (tile, Gaussian) pairs have alpha < amin at every pixel and would be skipped anyway."""
    for g in range(xmin.shape[0]):
        o = opac[g]
        if not o >= amin:
            xmax[g] = xmin[g]
            continue
        ca, cb, cc = conics[g, 0], conics[g, 1], conics[g, 2]
        det = ca * cc - cb * cb
        if not det > 0:
            continue
        r2 = -2.0 * np.log(amin / o)
        hx = np.sqrt(r2 * cc / det) + 1.0
        hy = np.sqrt(r2 * ca / det) + 1.0
        u, v = means2d[g, 0], means2d[g, 1]
        xmin[g] = max(xmin[g], np.int64(np.floor((u - hx) / TILE)))
        xmax[g] = min(xmax[g], np.int64(np.floor((u + hx) / TILE)) + 1)
        ymin[g] = max(ymin[g], np.int64(np.floor((v - hy) / TILE)))
        ymax[g] = min(ymax[g], np.int64(np.floor((v + hy) / TILE)) + 1)
        if xmax[g] < xmin[g]:
            xmax[g] = xmin[g]
        if ymax[g] < ymin[g]:
            ymax[g] = ymin[g]


@njit(cache=True)
def bin_tiles(xmin, xmax, ymin, ymax, order, tiles_x, n_tiles):
    """Depth-sorted tile lists. order: (N,) Gaussian ids sorted front to back.

    Returns offsets (T + 1,) int64 and gids (P,) int64 (see pd2gs.render.binning).
    """
    counts = np.zeros(n_tiles, np.int64)
    for g in range(xmin.shape[0]):
        for ty in range(ymin[g], ymax[g]):
            for tx in range(xmin[g], xmax[g]):
                counts[ty * tiles_x + tx] += 1
    offsets = np.zeros(n_tiles + 1, np.int64)
    for t in range(n_tiles):
        offsets[t + 1] = offsets[t] + counts[t]
    fill = offsets[:-1].copy()
    gids = np.empty(offsets[n_tiles], np.int64)
    for i in range(order.shape[0]):
        g = order[i]
        for ty in range(ymin[g], ymax[g]):
            for tx in range(xmin[g], xmax[g]):
                t = ty * tiles_x + tx
                gids[fill[t]] = g
                fill[t] += 1
    return offsets, gids


# consts layout (all in the working dtype), built by ``make_consts``.
C_AMAX, C_AMIN, C_TMIN, C_ONE, C_HALF, C_ZERO, C_LOG2E, C_LN2, C_CUT, C_Q4, C_Q16, C_Q256 = range(12)
C_POLY = 12  # 8 Taylor coefficients 1/j!, j = 0..7


def make_consts(dtype, alpha_max: float, alpha_min: float, t_min: float) -> np.ndarray:
    """Typed constants for the kernels (see C_* indices)."""
    vals = [alpha_max, alpha_min, t_min, 1.0, 0.5, 0.0, 1.4426950408889634, 0.6931471805599453,
            np.log(alpha_min) - 0.1, 0.25, 1.0 / 16, 1.0 / 256]
    fact = 1.0
    for j in range(8):
        fact *= max(j, 1)
        vals.append(1.0 / fact)
    return np.array(vals, dtype=dtype)


@njit(inline="always")
def _exp_consts(c):
    """Constants of ``_exp_neg`` as a tuple of scalars (keeps array loads out of the loops)."""
    return (c[C_HALF], c[C_ONE], c[C_ZERO], c[C_LOG2E], c[C_LN2], c[C_CUT],
            c[C_POLY], c[C_POLY + 1], c[C_POLY + 2], c[C_POLY + 3], c[C_POLY + 4],
            c[C_POLY + 5], c[C_POLY + 6], c[C_POLY + 7], c[C_HALF], c[C_Q4], c[C_Q16], c[C_Q256])


@njit(inline="always")
def _exp_neg(x, e):
    """exp(x) for x in [log(1/255) - 0.1, 0] by range reduction and a degree-7 Taylor
    polynomial (relative error ~1e-9); returns 0 below that range. Arithmetic and selects
    only, so the pixel loops vectorise (numba has no SIMD exp here). e = _exp_consts(c)."""
    nf = np.floor(x * e[3] + e[0])
    f = x - nf * e[4]
    p = ((((((e[13] * f + e[12]) * f + e[11]) * f + e[10]) * f + e[9]) * f + e[8]) * f
         + e[7]) * f + e[6]
    ok = x >= e[5]
    m = np.int64(-nf) if ok else np.int64(0)
    s = e[1]
    s = s * e[14] if (m & 1) != 0 else s
    s = s * e[15] if (m & 2) != 0 else s
    s = s * e[16] if (m & 4) != 0 else s
    s = s * e[17] if (m & 8) != 0 else s
    return p * s if ok else e[2]


@njit(inline="always")
def _row_range(my, ca, cb, cc, o, amin, y0):
    """Tile-local rows [lo, hi) where alpha >= amin is possible: the ellipse
    d^T conic d <= -2 log(amin / o), widened by one pixel for rounding. Empty if o < amin."""
    if not o >= amin:
        return 0, 0
    det = ca * cc - cb * cb
    r2 = -2.0 * np.log(amin / o)
    hy = np.sqrt(r2 * ca / det) + 1.0 if det > 0 else 1e30
    lo = max(0, np.int64(np.floor(my - hy)) - y0) if hy < 1e6 else 0
    hi = min(TILE, np.int64(np.ceil(my + hy)) - y0 + 1) if hy < 1e6 else TILE
    return lo, hi


@njit(fastmath=True)
def _sum(buf):
    """Sum of a 1-D array (reassociation allowed: vectorised)."""
    acc = buf[0] - buf[0]
    for i in range(buf.shape[0]):
        acc += buf[i]
    return acc


def tile_order(offsets: np.ndarray, threads: int) -> np.ndarray:
    """Tiles sorted by decreasing list length, dealt round-robin to the threads: prange splits
    its range into one contiguous block per thread, so block j holds ranks j, j + T, j + 2T...
    and every thread gets a similar share of heavy and light tiles. (T+0,) int64."""
    ranked = np.argsort(-(offsets[1:] - offsets[:-1]), kind="stable")
    return np.concatenate([ranked[j::max(threads, 1)] for j in range(max(threads, 1))])


@njit(parallel=True, cache=True, error_model="numpy")
def forward_kernel(offsets, gids, means2d, conics, opac, feat, width, height, tiles_x,
                   c, labels, lw_out, maxw_pair, order):
    """Front-to-back compositing of each 16x16 tile, Gaussians outer, the 256 pixels inner.

    c: constants from ``make_consts``. labels: (N,) int64 (used when lw_out has L > 0
    channels); lw_out: (H, W, L) output; maxw_pair: (P,) output (ignored when size 0).
    Returns feat_out (H, W, 4), trans (H, W), last (H, W) int64 = one past the last composited
    list entry of each pixel (the backward walks back from there).
    """
    dt = means2d.dtype
    one, zero = c[C_ONE], c[C_ZERO]
    out = np.zeros((height, width, 4), dt)
    trans = np.ones((height, width), dt)
    last = np.zeros((height, width), np.int64)
    n_lab = lw_out.shape[2]
    want_max = maxw_pair.shape[0] > 0
    amax, amin, tmin, half = c[C_AMAX], c[C_AMIN], c[C_TMIN], c[C_HALF]
    ec = _exp_consts(c)
    npx = TILE * TILE
    for i in prange(order.shape[0]):
        t = order[i]
        x0 = (t % tiles_x) * TILE
        y0 = (t // tiles_x) * TILE
        start, end = offsets[t], offsets[t + 1]
        px = np.empty(npx, dt)
        py = np.empty(npx, dt)
        act = np.zeros(npx, dt)
        T = np.ones(npx, dt)
        lst = np.zeros(npx, np.int64)
        a0 = np.zeros(npx, dt)
        a1 = np.zeros(npx, dt)
        a2 = np.zeros(npx, dt)
        a3 = np.zeros(npx, dt)
        wbuf = np.zeros(npx, dt)
        lw = np.zeros((max(n_lab, 1), npx), dt)
        for p in range(npx):
            px[p] = x0 + p % TILE
            py[p] = y0 + p // TILE
            if x0 + p % TILE < width and y0 + p // TILE < height:
                act[p] = one
        for k in range(start, end):
            if (k - start) % 32 == 31 and _sum(act) == zero:
                break
            g = gids[k]
            mx, my = means2d[g, 0], means2d[g, 1]
            ca, cb, cc, o = conics[g, 0], conics[g, 1], conics[g, 2], opac[g]
            f0, f1, f2, f3 = feat[g, 0], feat[g, 1], feat[g, 2], feat[g, 3]
            lo, hi = _row_range(my, ca, cb, cc, o, amin, y0)
            for p in range(lo * TILE, hi * TILE):
                dx = px[p] - mx
                dy = py[p] - my
                power = -half * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
                alpha = min(amax, o * _exp_neg(power, ec))
                tp = T[p]
                test = tp * (one - alpha)
                good = (power <= zero) & (alpha >= amin) & (act[p] > zero)
                contrib = good & (test >= tmin)
                stop = good & (test < tmin)
                w = alpha * tp if contrib else zero
                wbuf[p] = w
                a0[p] += w * f0
                a1[p] += w * f1
                a2[p] += w * f2
                a3[p] += w * f3
                T[p] = test if contrib else tp
                act[p] = zero if stop else act[p]
                lst[p] = k + 1 if contrib else lst[p]
            if n_lab > 0:
                lab = labels[g]
                for p in range(lo * TILE, hi * TILE):
                    lw[lab, p] += wbuf[p]
            if want_max:
                maxw_pair[k] = np.max(wbuf[lo * TILE:hi * TILE]) if hi > lo else zero
        for p in range(npx):
            x, y = x0 + p % TILE, y0 + p // TILE
            if x < width and y < height:
                out[y, x, 0] = a0[p]
                out[y, x, 1] = a1[p]
                out[y, x, 2] = a2[p]
                out[y, x, 3] = a3[p]
                trans[y, x] = T[p]
                last[y, x] = lst[p]
                for j in range(n_lab):
                    lw_out[y, x, j] = lw[j, p]
    return out, trans, last


@njit(parallel=True, cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def backward_kernel(offsets, gids, means2d, conics, opac, feat, width, height, tiles_x,
                    c, trans, last, g_feat, g_trans, order):
    """Exact gradients of ``forward_kernel``: each pixel walks its list back to front
    (transmittance recovered by division, as in 3DGS), Gaussians outer, pixels inner.

    g_feat: (H, W, 4) dL/dfeat_out, g_trans: (H, W) dL/dtrans.
    Returns pair_grad (P, 10): per list entry [dmean2d(2), dconic(3), dopacity, dfeat(4)].
    """
    dt = means2d.dtype
    one, zero, half = c[C_ONE], c[C_ZERO], c[C_HALF]
    amax, amin = c[C_AMAX], c[C_AMIN]
    ec = _exp_consts(c)
    pair_grad = np.zeros((gids.shape[0], 10), dt)
    npx = TILE * TILE
    for i in prange(order.shape[0]):
        t = order[i]
        x0 = (t % tiles_x) * TILE
        y0 = (t // tiles_x) * TILE
        start = offsets[t]
        px = np.empty(npx, dt)
        py = np.empty(npx, dt)
        T = np.ones(npx, dt)
        tf = np.ones(npx, dt)
        lst = np.zeros(npx, np.int64)
        g0 = np.zeros(npx, dt)
        g1 = np.zeros(npx, dt)
        g2 = np.zeros(npx, dt)
        g3 = np.zeros(npx, dt)
        gt = np.zeros(npx, dt)
        s0 = np.zeros(npx, dt)
        s1 = np.zeros(npx, dt)
        s2 = np.zeros(npx, dt)
        s3 = np.zeros(npx, dt)
        kmax = start
        for p in range(npx):
            x, y = x0 + p % TILE, y0 + p // TILE
            px[p] = x
            py[p] = y
            if x < width and y < height:
                T[p] = trans[y, x]
                tf[p] = trans[y, x]
                lst[p] = last[y, x]
                kmax = max(kmax, last[y, x])
                gt[p] = g_trans[y, x]
                g0[p] = g_feat[y, x, 0]
                g1[p] = g_feat[y, x, 1]
                g2[p] = g_feat[y, x, 2]
                g3[p] = g_feat[y, x, 3]
        for k in range(kmax - 1, start - 1, -1):
            g = gids[k]
            mx, my = means2d[g, 0], means2d[g, 1]
            ca, cb, cc, o = conics[g, 0], conics[g, 1], conics[g, 2], opac[g]
            f0, f1, f2, f3 = feat[g, 0], feat[g, 1], feat[g, 2], feat[g, 3]
            r0 = r1 = r2 = r3 = r4 = r5 = r6 = r7 = r8 = r9 = zero
            lo, hi = _row_range(my, ca, cb, cc, o, amin, y0)
            for p in range(lo * TILE, hi * TILE):
                dx = px[p] - mx
                dy = py[p] - my
                power = -half * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
                gauss = _exp_neg(power, ec)
                raw = o * gauss
                alpha = min(amax, raw)
                good = (power <= zero) & (alpha >= amin) & (k < lst[p])
                om = one - alpha
                tp = T[p]
                ti = tp / om if good else tp
                wt = alpha * ti if good else zero
                dal = ti * (g0[p] * (f0 - s0[p]) + g1[p] * (f1 - s1[p]) + g2[p] * (f2 - s2[p])
                            + g3[p] * (f3 - s3[p])) - gt[p] * tf[p] / om
                dal = dal if good else zero
                s0[p] = alpha * f0 + om * s0[p] if good else s0[p]
                s1[p] = alpha * f1 + om * s1[p] if good else s1[p]
                s2[p] = alpha * f2 + om * s2[p] if good else s2[p]
                s3[p] = alpha * f3 + om * s3[p] if good else s3[p]
                T[p] = ti
                dgeo = dal if raw <= amax else zero
                dpow = alpha * dgeo
                r0 += dpow * (ca * dx + cb * dy)
                r1 += dpow * (cb * dx + cc * dy)
                r2 += -half * dx * dx * dpow
                r3 += -dx * dy * dpow
                r4 += -half * dy * dy * dpow
                r5 += gauss * dgeo
                r6 += wt * g0[p]
                r7 += wt * g1[p]
                r8 += wt * g2[p]
                r9 += wt * g3[p]
            pair_grad[k, 0] = r0
            pair_grad[k, 1] = r1
            pair_grad[k, 2] = r2
            pair_grad[k, 3] = r3
            pair_grad[k, 4] = r4
            pair_grad[k, 5] = r5
            pair_grad[k, 6] = r6
            pair_grad[k, 7] = r7
            pair_grad[k, 8] = r8
            pair_grad[k, 9] = r9
    return pair_grad


@njit(cache=True)
def reduce_pairs(gids, pair_grad, n):
    """Sum per-entry gradients (P, 10) into per-Gaussian gradients (N, 10)."""
    out = np.zeros((n, pair_grad.shape[1]), pair_grad.dtype)
    for k in range(gids.shape[0]):
        g = gids[k]
        for j in range(pair_grad.shape[1]):
            out[g, j] += pair_grad[k, j]
    return out


@njit(cache=True)
def reduce_max(gids, pair_val, n):
    """Max of per-entry values (P,) per Gaussian -> (N,)."""
    out = np.zeros(n, pair_val.dtype)
    for k in range(gids.shape[0]):
        g = gids[k]
        if pair_val[k] > out[g]:
            out[g] = pair_val[k]
    return out
