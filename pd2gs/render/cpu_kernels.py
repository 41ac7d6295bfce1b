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
from numba import carray, njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic

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


@intrinsic
def _stack(typingctx, n, dtype):
    """Pointer to ``n`` (a literal) uninitialised elements of ``dtype`` on the stack."""
    if not isinstance(n, types.IntegerLiteral):
        return None
    ety = dtype.dtype if isinstance(dtype, types.DType) else dtype.instance_type

    def codegen(context, builder, sig, args):
        return cgutils.alloca_once(builder, context.get_value_type(ety), size=n.literal_value)

    return types.CPointer(ety)(n, dtype), codegen


# prep layout: per Gaussian
P_MX, P_MY, P_A, P_B, P_C, P_O, P_F0, P_F1, P_F2, P_F3, P_YLO, P_YHI, P_CA, P_CB, P_CC = range(15)
NPREP = 16
LOG2E = 1.4426950408889634
LN2 = 0.6931471805599453


@njit(cache=True, error_model="numpy")
def prep_gaussians(means2d, conics, opac, feat, amin):
    """Per-Gaussian packed constants: log2-scaled quadratic coefficients and the pixel rows
    [ylo, yhi) where alpha >= amin is possible (empty if o < amin)."""
    n = means2d.shape[0]
    out = np.zeros((n, NPREP), means2d.dtype)
    for g in range(n):
        mx, my = means2d[g, 0], means2d[g, 1]
        ca, cb, cc, o = conics[g, 0], conics[g, 1], conics[g, 2], opac[g]
        out[g, P_MX] = mx
        out[g, P_MY] = my
        out[g, P_A] = -0.5 * LOG2E * ca
        out[g, P_B] = -LOG2E * cb
        out[g, P_C] = -0.5 * LOG2E * cc
        out[g, P_O] = o
        out[g, P_F0] = feat[g, 0]
        out[g, P_F1] = feat[g, 1]
        out[g, P_F2] = feat[g, 2]
        out[g, P_F3] = feat[g, 3]
        out[g, P_CA] = ca
        out[g, P_CB] = cb
        out[g, P_CC] = cc
        if not o >= amin:
            out[g, P_YLO] = 0
            out[g, P_YHI] = 0
            continue
        det = ca * cc - cb * cb
        if det > 0:
            hy = np.sqrt(-2.0 * np.log(amin / o) * ca / det) + 1.0
            if hy < 1e6:
                out[g, P_YLO] = np.floor(my - hy)
                out[g, P_YHI] = np.ceil(my + hy) + 1
                continue
        out[g, P_YLO] = -1e9
        out[g, P_YHI] = 1e9
    return out

# constants layout (working dtype)
K_AMAX, K_AMIN, K_TMIN, K_ONE, K_HALF, K_ZERO, K_ZCUT = range(7)
K_POLY = 7  # 8 coefficients ln2^j / j!
K_Q = 15    # 1/256, 1/16, 1/4, 1/2
K_EIGHT, K_FOUR, K_TWO = 19, 20, 21


def make_consts(dtype, alpha_max: float, alpha_min: float, t_min: float) -> np.ndarray:
    vals = [alpha_max, alpha_min, t_min, 1.0, 0.5, 0.0, np.log2(alpha_min) - 0.2]
    fact = 1.0
    for j in range(8):
        fact *= max(j, 1)
        vals.append(LN2 ** j / fact)
    vals += [1.0 / 256, 1.0 / 16, 0.25, 0.5, 8.0, 4.0, 2.0]
    return np.array(vals, dtype=dtype)


@njit(inline="always")
def _ec(c):
    return (c[K_ZCUT], c[K_ZERO], c[K_HALF], c[K_POLY], c[K_POLY + 1], c[K_POLY + 2],
            c[K_POLY + 3], c[K_POLY + 4], c[K_POLY + 5], c[K_POLY + 6], c[K_POLY + 7],
            c[K_ONE], c[K_Q], c[K_Q + 1], c[K_Q + 2], c[K_Q + 3], c[K_EIGHT], c[K_FOUR],
            c[K_TWO])


@njit(inline="always")
def _exp2(z, e):
    """2**z for z in [zcut, 0] (z is clamped to that range; callers reject z > 0 and
    2**zcut < alpha_min). Degree-7 polynomial on the fraction, exact power-of-two scaling by
    selects, so the 16-pixel loops vectorise (relative error ~1e-9 in float64)."""
    zc = min(max(z, e[0]), e[1])
    nf = np.floor(zc + e[2])
    f = zc - nf
    p = ((((((e[10] * f + e[9]) * f + e[8]) * f + e[7]) * f + e[6]) * f + e[5]) * f
         + e[4]) * f + e[3]
    m = -nf
    s = e[11]
    b = m >= e[16]
    s = s * e[12] if b else s
    m = m - e[16] if b else m
    b = m >= e[17]
    s = s * e[13] if b else s
    m = m - e[17] if b else m
    b = m >= e[18]
    s = s * e[14] if b else s
    m = m - e[18] if b else m
    b = m >= e[11]
    s = s * e[15] if b else s
    return p * s


@njit(parallel=True, cache=True, error_model="numpy", fastmath={"contract"})
def forward_kernel(offsets, gids, prep, width, height, tiles_x, c, labels, lw_out, maxw_pair,
                   order):
    """Front-to-back compositing of each 16x16 tile: Gaussians outer, then the rows the
    Gaussian can reach, then the 16 pixels of a row (one SIMD vector in float32).
    Returns feat_out (H, W, 4), trans (H, W), last (H, W) int32."""
    dt = prep.dtype
    one, zero = c[K_ONE], c[K_ZERO]
    out = np.zeros((height, width, 4), dt)
    trans = np.ones((height, width), dt)
    last = np.zeros((height, width), np.int32)
    n_lab = lw_out.shape[2]
    want_max = maxw_pair.shape[0] > 0
    amax, amin, tmin = c[K_AMAX], c[K_AMIN], c[K_TMIN]
    ec = _ec(c)
    for i in prange(order.shape[0]):
        t = order[i]
        x0 = (t % tiles_x) * TILE
        y0 = (t // tiles_x) * TILE
        start, end = offsets[t], offsets[t + 1]
        xs = carray(_stack(16, dt), 16)
        ys = carray(_stack(16, dt), 16)
        T = carray(_stack(256, dt), (16, 16))
        act = carray(_stack(256, dt), (16, 16))
        a0 = carray(_stack(256, dt), (16, 16))
        a1 = carray(_stack(256, dt), (16, 16))
        a2 = carray(_stack(256, dt), (16, 16))
        a3 = carray(_stack(256, dt), (16, 16))
        wb = carray(_stack(256, dt), (16, 16))
        lst = carray(_stack(256, np.int32), (16, 16))
        row_alive = carray(_stack(16, dt), 16)
        lw = np.zeros((max(n_lab, 1), 16, 16), dt)
        for j in range(16):
            xs[j] = x0 + j
            ys[j] = y0 + j
        for r in range(16):
            for j in range(16):
                T[r, j] = one
                a0[r, j] = zero
                a1[r, j] = zero
                a2[r, j] = zero
                a3[r, j] = zero
                wb[r, j] = zero
                lst[r, j] = 0
                act[r, j] = one if (x0 + j < width and y0 + r < height) else zero
        for r in range(16):
            row_alive[r] = one
        for k in range(start, end):
            if (k - start) % 32 == 31:  # refresh which rows still have unterminated pixels
                alive = zero
                for r in range(16):
                    ar = act[r]
                    acc_r = zero
                    for j in range(16):
                        acc_r += ar[j]
                    row_alive[r] = acc_r
                    alive += acc_r
                if alive == zero:
                    break
            g = gids[k]
            mx, my = prep[g, P_MX], prep[g, P_MY]
            A, B, C, o = prep[g, P_A], prep[g, P_B], prep[g, P_C], prep[g, P_O]
            f0, f1, f2, f3 = prep[g, P_F0], prep[g, P_F1], prep[g, P_F2], prep[g, P_F3]
            lo = max(np.int64(prep[g, P_YLO]) - y0, 0)
            hi = min(np.int64(prep[g, P_YHI]) - y0, TILE)
            kk = np.int32(k + 1)
            for r in range(lo, hi):
                if row_alive[r] == zero:  # every pixel of the row has terminated: w = 0
                    for j in range(16):
                        wb[r, j] = zero
                    continue
                dy = ys[r] - my
                cy = C * dy * dy
                by = B * dy
                Tr, actr, wr, lr = T[r], act[r], wb[r], lst[r]
                a0r, a1r, a2r, a3r = a0[r], a1[r], a2[r], a3[r]
                for j in range(16):
                    dx = xs[j] - mx
                    z = (A * dx + by) * dx + cy
                    alpha = min(amax, o * _exp2(z, ec))
                    tp = Tr[j]
                    test = tp * (one - alpha)
                    good = (z <= zero) & (alpha >= amin) & (actr[j] > zero)
                    contrib = good & (test >= tmin)
                    stop = good & (test < tmin)
                    w = alpha * tp if contrib else zero
                    wr[j] = w
                    a0r[j] += w * f0
                    a1r[j] += w * f1
                    a2r[j] += w * f2
                    a3r[j] += w * f3
                    Tr[j] = test if contrib else tp
                    actr[j] = zero if stop else actr[j]
                    lr[j] = kk if contrib else lr[j]
            if n_lab > 0:
                lab = labels[g]
                for r in range(lo, hi):
                    for j in range(16):
                        lw[lab, r, j] += wb[r, j]
            if want_max:
                m = zero
                for r in range(lo, hi):
                    for j in range(16):
                        m = max(m, wb[r, j])
                maxw_pair[k] = m
        for r in range(16):
            for j in range(16):
                x, y = x0 + j, y0 + r
                if x < width and y < height:
                    out[y, x, 0] = a0[r, j]
                    out[y, x, 1] = a1[r, j]
                    out[y, x, 2] = a2[r, j]
                    out[y, x, 3] = a3[r, j]
                    trans[y, x] = T[r, j]
                    last[y, x] = lst[r, j]
                    for q in range(n_lab):
                        lw_out[y, x, q] = lw[q, r, j]
    return out, trans, last


@njit(parallel=True, cache=True, error_model="numpy", fastmath={"contract", "reassoc", "nsz"})
def backward_kernel(offsets, gids, prep, width, height, tiles_x, c, trans, last, g_feat,
                    g_trans, order):
    """Exact gradients of ``forward_kernel``: each pixel walks its list back to front
    (transmittance recovered by division, as in 3DGS), Gaussians outer, rows, 16 pixels.
    Returns pair_grad (P, 10): per list entry [dmean2d(2), dconic(3), dopacity, dfeat(4)]."""
    dt = prep.dtype
    one, zero, half = c[K_ONE], c[K_ZERO], c[K_HALF]
    amax, amin = c[K_AMAX], c[K_AMIN]
    ec = _ec(c)
    pair_grad = np.zeros((gids.shape[0], 10), dt)
    for i in prange(order.shape[0]):
        t = order[i]
        x0 = (t % tiles_x) * TILE
        y0 = (t // tiles_x) * TILE
        start = offsets[t]
        xs = carray(_stack(16, dt), 16)
        ys = carray(_stack(16, dt), 16)
        T = carray(_stack(256, dt), (16, 16))
        tf = carray(_stack(256, dt), (16, 16))
        lst = carray(_stack(256, np.int32), (16, 16))
        g0 = carray(_stack(256, dt), (16, 16))
        g1 = carray(_stack(256, dt), (16, 16))
        g2 = carray(_stack(256, dt), (16, 16))
        g3 = carray(_stack(256, dt), (16, 16))
        gt = carray(_stack(256, dt), (16, 16))
        s0 = carray(_stack(256, dt), (16, 16))
        s1 = carray(_stack(256, dt), (16, 16))
        s2 = carray(_stack(256, dt), (16, 16))
        s3 = carray(_stack(256, dt), (16, 16))
        acc = carray(_stack(160, dt), (10, 16))
        row_last = carray(_stack(16, np.int32), 16)
        for j in range(16):
            xs[j] = x0 + j
            ys[j] = y0 + j
        kmax = start
        for r in range(16):
            for j in range(16):
                x, y = x0 + j, y0 + r
                s0[r, j] = zero
                s1[r, j] = zero
                s2[r, j] = zero
                s3[r, j] = zero
                if x < width and y < height:
                    T[r, j] = trans[y, x]
                    tf[r, j] = trans[y, x]
                    lst[r, j] = last[y, x]
                    kmax = max(kmax, np.int64(last[y, x]))
                    gt[r, j] = g_trans[y, x]
                    g0[r, j] = g_feat[y, x, 0]
                    g1[r, j] = g_feat[y, x, 1]
                    g2[r, j] = g_feat[y, x, 2]
                    g3[r, j] = g_feat[y, x, 3]
                else:
                    T[r, j] = one
                    tf[r, j] = one
                    lst[r, j] = 0
                    gt[r, j] = zero
                    g0[r, j] = zero
                    g1[r, j] = zero
                    g2[r, j] = zero
                    g3[r, j] = zero
        for r in range(16):
            m = np.int32(0)
            for j in range(16):
                m = max(m, lst[r, j])
            row_last[r] = m
        for k in range(kmax - 1, start - 1, -1):
            g = gids[k]
            mx, my = prep[g, P_MX], prep[g, P_MY]
            A, B, C, o = prep[g, P_A], prep[g, P_B], prep[g, P_C], prep[g, P_O]
            ca, cb, cc = prep[g, P_CA], prep[g, P_CB], prep[g, P_CC]
            f0, f1, f2, f3 = prep[g, P_F0], prep[g, P_F1], prep[g, P_F2], prep[g, P_F3]
            lo = max(np.int64(prep[g, P_YLO]) - y0, 0)
            hi = min(np.int64(prep[g, P_YHI]) - y0, TILE)
            kk = np.int32(k)
            for q in range(10):
                for j in range(16):
                    acc[q, j] = zero
            for r in range(lo, hi):
                if kk >= row_last[r]:  # no pixel of the row composited entry k or an earlier one
                    continue
                dy = ys[r] - my
                cy = C * dy * dy
                by = B * dy
                Tr, tfr, lr, gtr = T[r], tf[r], lst[r], gt[r]
                g0r, g1r, g2r, g3r = g0[r], g1[r], g2[r], g3[r]
                s0r, s1r, s2r, s3r = s0[r], s1[r], s2[r], s3[r]
                for j in range(16):
                    dx = xs[j] - mx
                    z = (A * dx + by) * dx + cy
                    gauss = _exp2(z, ec)
                    raw = o * gauss
                    alpha = min(amax, raw)
                    good = (z <= zero) & (alpha >= amin) & (kk < lr[j])
                    om = one - alpha
                    inv = one / om
                    tp = Tr[j]
                    ti = tp * inv if good else tp
                    wt = alpha * ti if good else zero
                    dal = ti * (g0r[j] * (f0 - s0r[j]) + g1r[j] * (f1 - s1r[j])
                                + g2r[j] * (f2 - s2r[j]) + g3r[j] * (f3 - s3r[j])) \
                        - gtr[j] * tfr[j] * inv
                    dal = dal if good else zero
                    s0r[j] = alpha * f0 + om * s0r[j] if good else s0r[j]
                    s1r[j] = alpha * f1 + om * s1r[j] if good else s1r[j]
                    s2r[j] = alpha * f2 + om * s2r[j] if good else s2r[j]
                    s3r[j] = alpha * f3 + om * s3r[j] if good else s3r[j]
                    Tr[j] = ti
                    dgeo = dal if raw <= amax else zero
                    dpow = alpha * dgeo
                    acc[0, j] += dpow * (ca * dx + cb * dy)
                    acc[1, j] += dpow * (cb * dx + cc * dy)
                    acc[2, j] += -half * dx * dx * dpow
                    acc[3, j] += -dx * dy * dpow
                    acc[4, j] += -half * dy * dy * dpow
                    acc[5, j] += gauss * dgeo
                    acc[6, j] += wt * g0r[j]
                    acc[7, j] += wt * g1r[j]
                    acc[8, j] += wt * g2r[j]
                    acc[9, j] += wt * g3r[j]
            if hi > lo:
                for q in range(10):
                    tot = zero
                    for j in range(16):
                        tot += acc[q, j]
                    pair_grad[k, q] = tot
    return pair_grad


def tile_order(offsets: np.ndarray, threads: int) -> np.ndarray:
    """Tiles sorted by decreasing list length, dealt round-robin to the threads: prange splits
    its range into one contiguous block per thread, so block j holds ranks j, j + T, j + 2T...
    and every thread gets a similar share of heavy and light tiles. (T+0,) int64."""
    ranked = np.argsort(-(offsets[1:] - offsets[:-1]), kind="stable")
    return np.concatenate([ranked[j::max(threads, 1)] for j in range(max(threads, 1))])


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
