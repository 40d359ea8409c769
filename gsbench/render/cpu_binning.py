"""Depth order and tile binning of the `cpu` rasterizer: which 16x16 tiles each Gaussian's screen box
meets, front to back.

`depth_order` is np.argsort(z, kind="stable") as a radix sort (about 8x faster on 15k Gaussians).

The box-overlap test is the reference's (gsbench/render/torch_backend.py), in float64, so a
Gaussian is listed in exactly the tiles where the reference would composite it. Boxes are given
front to back, so each tile's list is in compositing order.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)


@njit(**_OPTS)
def _radix_argsort(keys):
    """Stable LSD radix argsort of unsigned integer keys, 11 bits per pass."""
    n = keys.size
    idx = np.arange(n)
    tmp = np.empty(n, idx.dtype)
    kk = keys.copy()
    kt = np.empty_like(kk)
    shift = 0
    while shift < 8 * keys.itemsize:
        cnt = np.zeros(2049, np.int64)
        for i in range(n):
            cnt[((kk[i] >> shift) & 2047) + 1] += 1
        for d in range(2048):
            cnt[d + 1] += cnt[d]
        for i in range(n):
            d = (kk[i] >> shift) & 2047
            o = cnt[d]
            tmp[o] = idx[i]
            kt[o] = kk[i]
            cnt[d] = o + 1
        idx, tmp = tmp, idx
        kk, kt = kt, kk
        shift += 11
    return idx


def depth_order(z: np.ndarray) -> np.ndarray:
    """Indices that sort the float32 or float64 depths z front to back, ties in index order: the
    same as np.argsort(z, kind="stable") (NaN last), from a radix sort."""
    z = np.ascontiguousarray(z)
    if z.dtype not in (np.float32, np.float64):
        raise ValueError(f"depth_order: float32 or float64 depths, got {z.dtype}")
    # unsigned integers in the order of the floats: IEEE bits with negatives flipped, NaN last
    u = np.uint32 if z.dtype == np.float32 else np.uint64
    bits = (z + z.dtype.type(0.0)).view(u)            # -0.0 + 0.0 = +0.0: the two zeros tie, as in numpy
    sign = u(1) << u(8 * z.itemsize - 1)
    keys = np.where(bits & sign, ~bits, bits | sign)
    keys[np.isnan(z)] = np.iinfo(u).max
    return _radix_argsort(keys)


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


@njit(parallel=True, **_OPTS)
def bin_tiles(x0, x1, y0, y1, width, height, tile_size, n_workers=1):
    """Per-tile lists of Gaussian ranks (boxes given front to back).

    Returns (tile_off (T+1,), ranks (P,)): the Gaussians of tile t are
    ranks[tile_off[t]:tile_off[t+1]], in depth order. Each of the n_workers prange iterations takes
    one run of consecutive ranks and writes its entries after those of the runs before it in every
    tile, so the lists are those of one serial pass whatever the number of workers.
    """
    tiles_x = (width + tile_size - 1) // tile_size
    tiles_y = (height + tile_size - 1) // tile_size
    n_tiles = tiles_x * tiles_y
    m = x0.size
    n_workers = max(1, min(n_workers, m))
    rng = np.empty((m, 4), np.int64)
    per = np.zeros((n_workers, n_tiles), np.int64)          # entries of worker w's run in tile t
    for w in prange(n_workers):
        for g in range(w * m // n_workers, (w + 1) * m // n_workers):
            xl, xh = _tile_range(x0[g], x1[g], width, tile_size, tiles_x)
            yl, yh = _tile_range(y0[g], y1[g], height, tile_size, tiles_y)
            rng[g, 0] = xl
            rng[g, 1] = xh
            rng[g, 2] = yl
            rng[g, 3] = yh
            for ty in range(yl, yh + 1):
                for tx in range(xl, xh + 1):
                    per[w, ty * tiles_x + tx] += 1
    counts = np.zeros(n_tiles + 1, np.int64)
    cursor = np.empty((n_workers, n_tiles), np.int64)     # where worker w writes next in tile t
    for t in range(n_tiles):
        c = counts[t]
        for w in range(n_workers):
            cursor[w, t] = c
            c += per[w, t]
        counts[t + 1] = c
    ranks = np.empty(counts[n_tiles], np.int32)
    for w in prange(n_workers):
        for g in range(w * m // n_workers, (w + 1) * m // n_workers):
            for ty in range(rng[g, 2], rng[g, 3] + 1):
                for tx in range(rng[g, 0], rng[g, 1] + 1):
                    t = ty * tiles_x + tx
                    ranks[cursor[w, t]] = g
                    cursor[w, t] += 1
    return counts, ranks
