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
backward) and pixels inner, in two passes: the exponent for all pixels of the tile (a plain loop
LLVM can vectorise), then the pixels it reaches. Per-pixel state (transmittance, colour behind,
done flag) lives in small per-tile arrays. The backward pass recovers the transmittance back to
front (T_k = T_{k+1} / (1 - alpha_k), float64) from the stored final float64 transmittance and
the index of the last contributing Gaussian, and sums each Gaussian's gradient over the tile's
pixels in row-major order into one float64 row per (tile, position). `reduce_rows` then sums each
Gaussian's rows in float64 in increasing tile order (one Gaussian per task) and adds the sum to its
gradient: a fixed order, so results are bit-identical for any thread count.
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

    Returns (tile_off (T+1,), ranks (P,), rank_off (M+1,), rank_pairs (P,)): the pairs of tile t
    are ranks[tile_off[t]:tile_off[t+1]] (depth order); the pair indices of Gaussian g are
    rank_pairs[rank_off[g]:rank_off[g+1]], in increasing tile order.
    """
    tiles_x = (width + tile_size - 1) // tile_size
    tiles_y = (height + tile_size - 1) // tile_size
    n_tiles = tiles_x * tiles_y
    m = x0.size
    rng = np.empty((m, 4), np.int64)
    counts = np.zeros(n_tiles + 1, np.int64)
    rank_off = np.zeros(m + 1, np.int64)
    for g in range(m):
        xl, xh = _tile_range(x0[g], x1[g], width, tile_size, tiles_x)
        yl, yh = _tile_range(y0[g], y1[g], height, tile_size, tiles_y)
        rng[g, 0] = xl
        rng[g, 1] = xh
        rng[g, 2] = yl
        rng[g, 3] = yh
        rank_off[g + 1] = rank_off[g] + max(0, xh - xl + 1) * max(0, yh - yl + 1)
        for ty in range(yl, yh + 1):
            for tx in range(xl, xh + 1):
                counts[ty * tiles_x + tx + 1] += 1
    for t in range(n_tiles):
        counts[t + 1] += counts[t]
    ranks = np.empty(counts[n_tiles], np.int32)
    rank_pairs = np.empty(counts[n_tiles], np.int64)
    cursor = counts[:n_tiles].copy()
    for g in range(m):
        k = rank_off[g]
        for ty in range(rng[g, 2], rng[g, 3] + 1):
            for tx in range(rng[g, 0], rng[g, 1] + 1):
                t = ty * tiles_x + tx
                ranks[cursor[t]] = g
                rank_pairs[k] = cursor[t]
                k += 1
                cursor[t] += 1
    return counts, ranks, rank_off, rank_pairs


@njit(inline="always", **_OPTS)
def _tile_pixels(t, tiles_x, tile_size, width, height, pxc, pyc, qx, qy):
    """Pixel-centre coordinates of tile t, row-major, into qx/qy. Returns (xa, ya, tile width, P)."""
    ty = t // tiles_x
    tx = t - ty * tiles_x
    xa = tx * tile_size
    ya = ty * tile_size
    tw = min(width, xa + tile_size) - xa
    th = min(height, ya + tile_size) - ya
    for p in range(tw * th):
        qx[p] = pxc[xa + p % tw]
        qy[p] = pyc[ya + p // tw]
    return xa, ya, tw, tw * th


@njit(inline="always", **_OPTS)
def _powers(qx, qy, n_pix, mx, my, a, b, c, mhalf, pw):
    """Exponent of one Gaussian at every pixel of a tile (a plain loop LLVM can vectorise)."""
    for p in range(n_pix):
        dx = qx[p] - mx
        dy = qy[p] - my
        pw[p] = mhalf * (a * dx * dx + c * dy * dy) - b * dx * dy


@njit(parallel=True, **_OPTS)
def raster_forward(gp, ch, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts,
                   out, t_out, t64_out, last_out):
    """Fused forward: all channels of every pixel, one tile per task.

    Gaussians are visited front to back; for each, the exponent is computed for all pixels of the
    tile at once (vectorised), then the pixels it reaches are composited. Writes out (H,W,C)
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
    n_max = tile_size * tile_size
    for t in prange(n_tiles):
        qx = np.empty(n_max, gp.dtype)
        qy = np.empty(n_max, gp.dtype)
        xa, ya, tw, n_pix = _tile_pixels(t, tiles_x, tile_size, width, height, pxc, pyc, qx, qy)
        pw = np.empty(n_pix, gp.dtype)
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
        for j in range(n):
            g = ranks[start + j]
            thr = gp[g, THR]
            op = gp[g, OP]
            _powers(qx, qy, n_pix, gp[g, MX], gp[g, MY], gp[g, CA], gp[g, CB], gp[g, CC], mhalf, pw)
            for p in range(n_pix):
                power = pw[p]
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
    contribution of the tile's j-th Gaussian, summed over the tile's pixels in row-major order.

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
    n_max = tile_size * tile_size
    for i in prange(t_hi - t_lo):
        t = t_lo + i
        start = tile_off[t]
        n = tile_off[t + 1] - start
        r0 = start - base
        if n == 0:
            continue
        qx = np.empty(n_max, gp.dtype)
        qy = np.empty(n_max, gp.dtype)
        xa, ya, tw, n_pix = _tile_pixels(t, tiles_x, tile_size, width, height, pxc, pyc, qx, qy)
        pw = np.empty(n_pix, gp.dtype)
        tr = np.empty(n_pix, np.float64)
        t_fin = np.empty(n_pix, np.float64)
        g_tf = np.empty(n_pix, np.float64)
        last = np.empty(n_pix, np.int64)
        gc = np.empty((n_pix, n_ch), np.float64)
        s = np.zeros((n_pix, n_ch), np.float64)
        acc = np.empty(n_cols, np.float64)
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
            _powers(qx, qy, n_pix, mx, my, a, b, c, mhalf, pw)
            for k in range(n_cols):
                acc[k] = 0.0
            for p in range(n_pix):
                if j >= last[p]:
                    continue
                power = pw[p]
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
                    dx = np.float64(qx[p] - mx)
                    dy = np.float64(qy[p] - my)
                    acc[G_OP] += d_alpha * np.float64(G)
                    acc[G_MX] += d_pow * (a64 * dx + b64 * dy)
                    acc[G_MY] += d_pow * (b64 * dx + c64 * dy)
                    acc[G_CA] += d_pow * (-0.5 * dx * dx)
                    acc[G_CB] += d_pow * (-dx * dy)
                    acc[G_CC] += d_pow * (-0.5 * dy * dy)
            for k in range(n_cols):
                rows[r0 + j, k] = acc[k]


@njit(parallel=True, **_OPTS)
def reduce_rows(rank_off, rank_pairs, order, p_lo, p_hi, rows, out):
    """out[order[g]] += sum of Gaussian g's rows among pairs [p_lo, p_hi), in tile order.

    One Gaussian per task; the sum is float64 in increasing tile order and is added to `out`
    (the working dtype, field order) once per wave: a fixed order for any thread count.
    """
    n_cols = rows.shape[1]
    for g in prange(rank_off.size - 1):
        k0 = rank_off[g]
        k1 = rank_off[g + 1]
        if k0 == k1 or rank_pairs[k1 - 1] < p_lo or rank_pairs[k0] >= p_hi:
            continue
        o = order[g]
        for c in range(n_cols):
            acc = 0.0
            for k in range(k0, k1):
                q = rank_pairs[k]
                if q >= p_lo and q < p_hi:
                    acc += rows[q - p_lo, c]
            out[o, c] += acc

