"""Numba kernels of the `cpu` rasterizer: tile binning, fused forward, hand-written backward.

All kernels work on Gaussians already sorted front to back (camera-space z, stable by index), so
a tile's list of Gaussian ranks is increasing and equals the compositing order.

Per-Gaussian parameters are packed in one (M, NPARAM) array `gp` of the working dtype (float32 or
float64; numba compiles one specialisation per dtype and caches it on disk):
    gp[:, MX], gp[:, MY]      screen position (pixel units, pixel centres at +0.5)
    gp[:, CA], gp[:, CB], gp[:, CC]  conic (inverse 2D covariance [[a, b], [b, c]])
    gp[:, OP]                 opacity
    gp[:, THR]                a conservative "cannot reach ALPHA_MIN" bound on the exponent:
                              log(ALPHA_MIN / opacity) - 1e-3. A pair with power < THR has
                              opacity * exp(power) < ALPHA_MIN / 1.001, so it is skipped without
                              evaluating exp; the decision equals the reference's to the bit.
`consts` holds the rules' constants in the working dtype so that every comparison is done in
that dtype, exactly as PyTorch compares a float32 tensor with a Python scalar.

Numerical mirror of the `torch` reference (gsbench/render/torch_backend.py):
- power, exp, alpha = min(opacity * G, ALPHA_MAX) and 1 - alpha in the working dtype, with the
  reference's operation order (no FMA contraction: fastmath is off);
- transmittance is a float64 running product of (1 - alpha) rounded to the working dtype at each
  step, as torch.cumprod does on the CPU; a pixel stops before the Gaussian whose rounded
  transmittance would be <= T_MIN;
- the weight of Gaussian k is alpha_k * T_k in the working dtype; channel sums are float64.
Loop order: per tile, Gaussians outer (front to back in the forward, back to front in the
backward) and pixels inner, row by row, restricted to the columns where the computed exponent can
reach the skip bound (`_col_range`: a rigorous bound, so the decisions are those of evaluating
every pixel). Per-pixel state (transmittance, colour behind, done flag) lives in small per-tile
arrays. The backward pass recovers the transmittance back to front (T_k = T_{k+1} / (1 - alpha_k),
float64) from the stored final float64 transmittance and
the index of the last contributing Gaussian, and sums each Gaussian's gradient over the tile's
pixels in row-major order in float64, stored as one row per (tile, position) in the working
dtype. `reduce_rows` then adds the rows into the per-Gaussian gradients (working dtype) serially
in row order (tile index, then depth rank): a fixed order, so results are bit-identical for any
thread count.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

MX, MY, CA, CB, CC, OP, THR = 0, 1, 2, 3, 4, 5, 6
NPARAM = 8                      # padded to 8 values per Gaussian
# gradient row layout: d means2d (x, y), d conic (a, b, c), d opacity, then d channel 0..C-1
G_MX, G_MY, G_CA, G_CB, G_CC, G_OP, G_CH = 0, 1, 2, 3, 4, 5, 6
# consts layout
K_ONE, K_MHALF, K_ZERO, K_AMAX, K_AMIN, K_TMIN = 0, 1, 2, 3, 4, 5
NCONST = 6

_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)


@njit(inline="always", **_OPTS)
def _tile_range(v0, v1, size, tile_size, n_tiles):
    """Tiles t whose pixel span [t*ts, min(size, (t+1)*ts)] meets the box [v0, v1] (reference test)."""
    lim = 2.0 * tile_size
    f0 = min(max(np.float64(v0), -lim), size + lim)
    f1 = min(max(np.float64(v1), -lim), size + lim)
    c_lo = max(0, int(np.floor(f0 / tile_size)) - 1)
    c_hi = min(n_tiles - 1, int(np.floor(f1 / tile_size)) + 1)
    lo = n_tiles
    hi = -1
    for t in range(c_lo, c_hi + 1):
        a = t * tile_size
        b = min(size, a + tile_size)
        if v1 >= a and v0 <= b:
            lo = min(lo, t)
            hi = max(hi, t)
    return lo, hi


@njit(**_OPTS)
def bin_tiles(x0, x1, y0, y1, width, height, tile_size):
    """Per-tile lists of Gaussian ranks (boxes given front to back).

    Returns (tile_off (T+1,), ranks (P,)): the Gaussians of tile t are
    ranks[tile_off[t]:tile_off[t+1]], in depth order.
    """
    tiles_x = (width + tile_size - 1) // tile_size
    tiles_y = (height + tile_size - 1) // tile_size
    n_tiles = tiles_x * tiles_y
    m = x0.size
    rng = np.empty((m, 4), np.int64)
    counts = np.zeros(n_tiles + 1, np.int64)
    for g in range(m):
        xl, xh = _tile_range(x0[g], x1[g], width, tile_size, tiles_x)
        yl, yh = _tile_range(y0[g], y1[g], height, tile_size, tiles_y)
        rng[g, 0] = xl
        rng[g, 1] = xh
        rng[g, 2] = yl
        rng[g, 3] = yh
        for ty in range(yl, yh + 1):
            for tx in range(xl, xh + 1):
                counts[ty * tiles_x + tx + 1] += 1
    for t in range(n_tiles):
        counts[t + 1] += counts[t]
    ranks = np.empty(counts[n_tiles], np.int32)
    cursor = counts[:n_tiles].copy()
    for g in range(m):
        for ty in range(rng[g, 2], rng[g, 3] + 1):
            for tx in range(rng[g, 0], rng[g, 1] + 1):
                t = ty * tiles_x + tx
                ranks[cursor[t]] = g
                cursor[t] += 1
    return counts, ranks


@njit(inline="always", **_OPTS)
def _tile_box(t, tiles_x, tile_size, width, height):
    """First pixel column and row, width and pixel count of tile t."""
    ty = t // tiles_x
    tx = t - ty * tiles_x
    xa = tx * tile_size
    ya = ty * tile_size
    tw = min(width, xa + tile_size) - xa
    th = min(height, ya + tile_size) - ya
    return xa, ya, tw, tw * th


@njit(inline="always", **_OPTS)
def _col_range(dy, mx, a, b, c, thr, xa, tw):
    """Columns [i_lo, i_hi] of a tile row where the computed exponent can reach `thr` (i_lo > i_hi: none).

    Exact, not a heuristic: along a row the exponent is the parabola
    -a/2 (dx + b dy / a)^2 - dy^2 (c - b^2 / a) / 2, and the value computed in the working dtype
    differs from it by less than 1e-5 (|a| dx^2 + |c| dy^2 + 2 |b dx dy|) (30x the float32
    rounding bound of the five operations), so every pixel outside the returned columns (widened
    by one pixel for the rounding of dx) has a computed exponent < thr and would be skipped anyway.
    """
    a64 = np.float64(a)
    b64 = np.float64(b)
    c64 = np.float64(c)
    dy64 = np.float64(dy)
    mx64 = np.float64(mx)
    if not (a64 > 0.0):
        return 0, tw - 1
    dxm = max(abs(xa + 0.5 - mx64), abs(xa + tw - 0.5 - mx64)) + 1.0
    err = 1e-5 * (abs(a64) * dxm * dxm + abs(c64) * dy64 * dy64 + 2.0 * abs(b64) * dxm * abs(dy64))
    peak = -0.5 * dy64 * dy64 * (c64 - b64 * b64 / a64)
    slack = peak + err - np.float64(thr)
    slack += 1e-9 * (abs(peak) + abs(np.float64(thr)))
    if not (slack >= 0.0):
        return 1, 0
    half = np.sqrt(2.0 * slack / a64) + 1.0
    centre = mx64 - b64 * dy64 / a64 - 0.5 - xa      # column index where dx + b dy / a = 0
    lo = min(max(centre - half, -1.0), tw + 1.0)
    hi = min(max(centre + half, -1.0), tw + 1.0)
    return max(0, int(np.ceil(lo))), min(tw - 1, int(np.floor(hi)))


@njit(parallel=True, **_OPTS)
def raster_forward(gp, ch, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts,
                   out, t_out, t64_out, last_out):
    """Fused forward: all channels of every pixel, one tile per task.

    Gaussians are visited front to back; each is composited into the pixels of each tile row
    that `_col_range` leaves (exactly those whose exponent can pass the rules). Writes out (H,W,C)
    channel sums, t_out (H,W) final transmittance (working dtype), t64_out (H,W) the same in
    float64 and last_out (H,W) = 1 + tile-list position of the last contributing Gaussian.
    """
    height, width, n_ch = out.shape
    n_tiles = tile_off.size - 1
    one = consts[K_ONE]
    zero = consts[K_ZERO]
    mhalf = consts[K_MHALF]
    amax = consts[K_AMAX]
    amin = consts[K_AMIN]
    tmin = consts[K_TMIN]
    for t in prange(n_tiles):
        xa, ya, tw, n_pix = _tile_box(t, tiles_x, tile_size, width, height)
        t64 = np.ones(n_pix, np.float64)
        t_w = np.empty(n_pix, gp.dtype)        # transmittance before the next Gaussian, working dtype
        rnd = np.empty(1, gp.dtype)             # rounds a float64 to the working dtype
        done = np.zeros(n_pix, np.bool_)
        lastj = np.zeros(n_pix, np.int32)
        acc = np.zeros((n_pix, n_ch), np.float64)
        for p in range(n_pix):
            t_w[p] = one
        n_live = n_pix
        start = tile_off[t]
        n = tile_off[t + 1] - start
        th = n_pix // tw
        for j in range(n):
            g = ranks[start + j]
            mx = gp[g, MX]
            my = gp[g, MY]
            a = gp[g, CA]
            b = gp[g, CB]
            c = gp[g, CC]
            op = gp[g, OP]
            thr = gp[g, THR]
            for row in range(th):
                dy = pyc[ya + row] - my
                i_lo, i_hi = _col_range(dy, mx, a, b, c, thr, xa, tw)
                for i in range(i_lo, i_hi + 1):
                    p = row * tw + i
                    dx = pxc[xa + i] - mx
                    power = mhalf * (a * dx * dx + c * dy * dy) - b * dx * dy
                    if not (power <= zero) or power < thr or done[p]:
                        continue
                    alpha = min(op * np.exp(power), amax)
                    if not (alpha >= amin):
                        continue
                    t64_next = t64[p] * (one - alpha)
                    rnd[0] = t64_next
                    t_next = rnd[0]
                    if not (t_next > tmin):          # stop before this Gaussian
                        done[p] = True
                        n_live -= 1
                        continue
                    w = alpha * t_w[p]
                    for k in range(n_ch):
                        acc[p, k] += w * ch[g, k]
                    t64[p] = t64_next
                    t_w[p] = t_next
                    lastj[p] = j + 1
            if n_live == 0:
                break
        for p in range(n_pix):
            py = ya + p // tw
            px = xa + p % tw
            for k in range(n_ch):
                out[py, px, k] = acc[p, k]
            t_out[py, px] = t64[p]
            t64_out[py, px] = t64[p]
            last_out[py, px] = lastj[p]


@njit(parallel=True, **_OPTS)
def raster_backward(gp, ch, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts,
                    t64_in, last_in, g_out, g_t, t_lo, t_hi, rows):
    """Gradient rows of tiles [t_lo, t_hi): row tile_off[t] - tile_off[t_lo] + j is the gradient
    contribution of the tile's j-th Gaussian, summed in float64 over the tile's pixels in
    row-major order and stored in the dtype of `rows`.

    Gaussians are visited back to front; every pixel carries its transmittance (recovered as
    T_j = T_{j+1} / (1 - alpha_j) from the stored final value) and the colour behind it.
    """
    height, width, n_ch = g_out.shape
    one = consts[K_ONE]
    zero = consts[K_ZERO]
    mhalf = consts[K_MHALF]
    amax = consts[K_AMAX]
    amin = consts[K_AMIN]
    base = tile_off[t_lo]
    n_cols = rows.shape[1]
    for ti in prange(t_hi - t_lo):
        t = t_lo + ti
        start = tile_off[t]
        n = tile_off[t + 1] - start
        r0 = start - base
        if n == 0:
            continue
        xa, ya, tw, n_pix = _tile_box(t, tiles_x, tile_size, width, height)
        tr = np.empty(n_pix, np.float64)
        t_fin = np.empty(n_pix, np.float64)
        g_tf = np.empty(n_pix, np.float64)
        last = np.empty(n_pix, np.int64)
        gc = np.empty((n_pix, n_ch), np.float64)
        s = np.zeros((n_pix, n_ch), np.float64)
        acc = np.empty(n_cols, np.float64)
        th = n_pix // tw
        j_top = 0
        for p in range(n_pix):
            py = ya + p // tw
            px = xa + p % tw
            t_fin[p] = t64_in[py, px]
            tr[p] = t_fin[p]
            g_tf[p] = g_t[py, px]
            last[p] = last_in[py, px]
            j_top = max(j_top, last[p])
            for k in range(n_ch):
                gc[p, k] = g_out[py, px, k]
        for j in range(j_top, n):
            for k in range(n_cols):
                rows[r0 + j, k] = 0.0
        for j in range(j_top - 1, -1, -1):
            g = ranks[start + j]
            mx = gp[g, MX]
            my = gp[g, MY]
            a = gp[g, CA]
            b = gp[g, CB]
            c = gp[g, CC]
            op = gp[g, OP]
            thr = gp[g, THR]
            a64 = np.float64(a)
            b64 = np.float64(b)
            c64 = np.float64(c)
            for k in range(n_cols):
                acc[k] = 0.0
            for row in range(th):
                dy = pyc[ya + row] - my
                i_lo, i_hi = _col_range(dy, mx, a, b, c, thr, xa, tw)
                for i in range(i_lo, i_hi + 1):
                    p = row * tw + i
                    if j >= last[p]:
                        continue
                    dx = pxc[xa + i] - mx
                    power = mhalf * (a * dx * dx + c * dy * dy) - b * dx * dy
                    if not (power <= zero) or power < thr:
                        continue
                    G = np.exp(power)
                    raw = op * G
                    alpha = min(raw, amax)
                    if not (alpha >= amin):
                        continue
                    al64 = np.float64(alpha)
                    om = np.float64(one - alpha)
                    tr[p] = tr[p] / om                 # transmittance before Gaussian j
                    w = al64 * tr[p]
                    d_alpha = 0.0
                    for k in range(n_ch):
                        cv = np.float64(ch[g, k])
                        acc[G_CH + k] += w * gc[p, k]
                        d_alpha += gc[p, k] * (cv - s[p, k])
                        s[p, k] = al64 * cv + om * s[p, k]
                    d_alpha = d_alpha * tr[p] - g_tf[p] * t_fin[p] / om
                    if raw <= amax:                    # no gradient through the clamp
                        d_pow = d_alpha * np.float64(raw)
                        dx64 = np.float64(dx)
                        dy64 = np.float64(dy)
                        acc[G_OP] += d_alpha * np.float64(G)
                        acc[G_MX] += d_pow * (a64 * dx64 + b64 * dy64)
                        acc[G_MY] += d_pow * (b64 * dx64 + c64 * dy64)
                        acc[G_CA] += d_pow * (-0.5 * dx64 * dx64)
                        acc[G_CB] += d_pow * (-dx64 * dy64)
                        acc[G_CC] += d_pow * (-0.5 * dy64 * dy64)
            for k in range(n_cols):
                rows[r0 + j, k] = acc[k]


@njit(**_OPTS)
def reduce_rows(tile_off, ranks, order, t_lo, t_hi, rows, out):
    """out[order[rank]] += rows, in row order (tile index, then depth rank): a fixed order.

    Serial on purpose: it is O(pairs x columns), a small fraction of the rasterization, and the
    order of the additions must not depend on scheduling.
    """
    base = tile_off[t_lo]
    n_cols = rows.shape[1]
    for r in range(tile_off[t_hi] - base):
        o = order[ranks[base + r]]
        for k in range(n_cols):
            out[o, k] += rows[r, k]
