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
- power, exp, alpha = min(opacity * G, ALPHA_MAX) and 1 - alpha in the working dtype;
- transmittance is a float64 running product of (1 - alpha) rounded to the working dtype at each
  step, as torch.cumprod does on the CPU; a pixel stops before the Gaussian whose rounded
  transmittance would be <= T_MIN;
- the weight of Gaussian k is alpha_k * T_k in the working dtype; channel sums are float64.
The backward pass recomputes alpha with the same inline function, recovers the transmittance back
to front (T_k = T_{k+1} / (1 - alpha_k), float64) from the stored final float64 transmittance and
the index of the last contributing Gaussian, and writes each pair's gradient into a per-(tile,
position) float64 row. `reduce_rows` then adds rows into per-Gaussian gradients in row order
(tile index, then depth rank): a fixed order, so results are bit-identical for any thread count.
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
def _pair(pxv, pyv, lp, j, consts):
    """Alpha of Gaussian j at one pixel centre. Returns (used, alpha, G, raw, dx, dy)."""
    dx = pxv - lp[j, MX]
    dy = pyv - lp[j, MY]
    power = consts[K_MHALF] * (lp[j, CA] * dx * dx + lp[j, CC] * dy * dy) - lp[j, CB] * dx * dy
    zero = consts[K_ZERO]
    if not (power <= zero) or power < lp[j, THR]:
        return False, zero, zero, zero, dx, dy
    G = np.exp(power)
    raw = lp[j, OP] * G
    alpha = min(raw, consts[K_AMAX])
    if not (alpha >= consts[K_AMIN]):
        return False, zero, zero, zero, dx, dy
    return True, alpha, G, raw, dx, dy


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
    """Per-tile lists of Gaussian ranks (boxes given front to back). Returns (offsets, ranks)."""
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


@njit(parallel=True, **_OPTS)
def raster_forward(gp, ch, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts,
                   out, t_out, t64_out, last_out):
    """Fused forward: all channels of every pixel, one tile per task.

    Writes out (H,W,C) channel sums, t_out (H,W) final transmittance in the working dtype,
    t64_out (H,W) the same in float64 and last_out (H,W) 1 + position of the last contributor.
    """
    height, width, n_ch = out.shape
    n_tiles = tile_off.size - 1
    one = consts[K_ONE]
    tmin = consts[K_TMIN]
    for t in prange(n_tiles):
        ty = t // tiles_x
        tx = t - ty * tiles_x
        xa = tx * tile_size
        xb = min(width, xa + tile_size)
        ya = ty * tile_size
        yb = min(height, ya + tile_size)
        start = tile_off[t]
        n = tile_off[t + 1] - start
        lp = np.empty((n, NPARAM), gp.dtype)
        lc = np.empty((n, n_ch), ch.dtype)
        for j in range(n):
            g = ranks[start + j]
            for k in range(NPARAM):
                lp[j, k] = gp[g, k]
            for c in range(n_ch):
                lc[j, c] = ch[g, c]
        acc = np.empty(n_ch, np.float64)
        for py in range(ya, yb):
            pyv = pyc[py]
            for px in range(xa, xb):
                pxv = pxc[px]
                for c in range(n_ch):
                    acc[c] = 0.0
                t64 = 1.0
                t_w = one                      # transmittance before Gaussian j, working dtype
                lastj = 0
                for j in range(n):
                    used, alpha, G, raw, dx, dy = _pair(pxv, pyv, lp, j, consts)
                    if not used:
                        continue
                    t64_next = t64 * (one - alpha)
                    t_out[py, px] = t64_next       # round to the working dtype (as torch.cumprod)
                    t_next = t_out[py, px]
                    if not (t_next > tmin):
                        break
                    w = alpha * t_w
                    for c in range(n_ch):
                        acc[c] += w * lc[j, c]
                    t64 = t64_next
                    t_w = t_next
                    lastj = j + 1
                for c in range(n_ch):
                    out[py, px, c] = acc[c]
                t_out[py, px] = t64
                t64_out[py, px] = t64
                last_out[py, px] = lastj


@njit(parallel=True, **_OPTS)
def raster_backward(gp, ch, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts,
                    t64_in, last_in, g_out, g_t, t_lo, t_hi, rows):
    """Per-pair gradients of tiles [t_lo, t_hi) into rows[tile_off[t] - tile_off[t_lo] + j]."""
    height, width, n_ch = g_out.shape
    one = consts[K_ONE]
    amax = consts[K_AMAX]
    base = tile_off[t_lo]
    n_cols = rows.shape[1]
    for i in prange(t_hi - t_lo):
        t = t_lo + i
        ty = t // tiles_x
        tx = t - ty * tiles_x
        xa = tx * tile_size
        xb = min(width, xa + tile_size)
        ya = ty * tile_size
        yb = min(height, ya + tile_size)
        start = tile_off[t]
        n = tile_off[t + 1] - start
        r0 = start - base
        for j in range(n):
            for k in range(n_cols):
                rows[r0 + j, k] = 0.0
        if n == 0:
            continue
        lp = np.empty((n, NPARAM), gp.dtype)
        lc = np.empty((n, n_ch), np.float64)
        for j in range(n):
            g = ranks[start + j]
            for k in range(NPARAM):
                lp[j, k] = gp[g, k]
            for c in range(n_ch):
                lc[j, c] = ch[g, c]
        s = np.empty(n_ch, np.float64)
        gc = np.empty(n_ch, np.float64)
        for py in range(ya, yb):
            pyv = pyc[py]
            for px in range(xa, xb):
                nlast = last_in[py, px]
                if nlast == 0:
                    continue
                pxv = pxc[px]
                t_fin = t64_in[py, px]
                tr = t_fin
                g_tf = np.float64(g_t[py, px])
                for c in range(n_ch):
                    gc[c] = g_out[py, px, c]
                    s[c] = 0.0
                for j in range(nlast - 1, -1, -1):
                    used, alpha, G, raw, dx, dy = _pair(pxv, pyv, lp, j, consts)
                    if not used:
                        continue
                    a64 = np.float64(alpha)
                    om = np.float64(one - alpha)
                    tr = tr / om                 # transmittance before Gaussian j
                    w = a64 * tr
                    r = r0 + j
                    d_alpha = 0.0
                    for c in range(n_ch):
                        cv = lc[j, c]
                        rows[r, G_CH + c] += w * gc[c]
                        d_alpha += gc[c] * (cv - s[c])
                        s[c] = a64 * cv + om * s[c]
                    d_alpha = d_alpha * tr - g_tf * t_fin / om
                    if raw <= amax:              # no gradient through the clamp
                        d_pow = d_alpha * np.float64(raw)
                        dx64 = np.float64(dx)
                        dy64 = np.float64(dy)
                        a = np.float64(lp[j, CA])
                        b = np.float64(lp[j, CB])
                        c2 = np.float64(lp[j, CC])
                        rows[r, G_OP] += d_alpha * np.float64(G)
                        rows[r, G_MX] += d_pow * (a * dx64 + b * dy64)
                        rows[r, G_MY] += d_pow * (b * dx64 + c2 * dy64)
                        rows[r, G_CA] += d_pow * (-0.5 * dx64 * dx64)
                        rows[r, G_CB] += d_pow * (-dx64 * dy64)
                        rows[r, G_CC] += d_pow * (-0.5 * dy64 * dy64)


@njit(parallel=True, **_OPTS)
def reduce_rows(tile_off, ranks, t_lo, t_hi, rows, grad):
    """grad[rank] += rows in row order (tile, then rank): one column per task, fixed order."""
    base = tile_off[t_lo]
    n_rows = tile_off[t_hi] - base
    for k in prange(rows.shape[1]):
        for r in range(n_rows):
            grad[ranks[base + r], k] += rows[r, k]
