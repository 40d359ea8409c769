"""Rigorous bounds of where a Gaussian can pass the `cpu` rasterizer's skip test in a tile.

A pixel is skipped when its computed exponent is below the Gaussian's THR (gsbench/render/cpu_kernels.py);
these bounds say which rows and columns of a tile can hold a pixel that is not, with margins for the
rounding of the working dtype, so walking only them gives exactly the result of walking the whole tile.
"""
from __future__ import annotations

import numpy as np
from numba import njit

_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)


@njit(inline="always", **_OPTS)
def _span(centre, half, n):
    """Indices [lo, hi] of 0..n-1 within `half` of `centre` (lo > hi: none), clamped before the
    float -> int conversion so that huge or infinite bounds stay in range."""
    lo = min(max(centre - half, -1.0), n + 1.0)
    hi = min(max(centre + half, -1.0), n + 1.0)
    return max(0, int(np.ceil(lo))), min(n - 1, int(np.floor(hi)))


@njit(inline="always", **_OPTS)
def col_range(dy, mx, a, b, c, thr, xa, tw):
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
    return _span(mx64 - b64 * dy64 / a64 - 0.5 - xa, half, tw)   # centre: the column where dx + b dy / a = 0


@njit(inline="always", **_OPTS)
def _allowance(my, mx, a, b, c, xa, ya, tw, th):
    """`col_range`'s error allowance at the tile's farthest column and row (float64): its largest value
    over the tile."""
    a64 = np.float64(a)
    b64 = np.float64(b)
    c64 = np.float64(c)
    dxm = max(abs(xa + 0.5 - np.float64(mx)), abs(xa + tw - 0.5 - np.float64(mx))) + 1.0
    dym = max(abs(ya + 0.5 - np.float64(my)), abs(ya + th - 0.5 - np.float64(my))) + 1.0
    return 1e-5 * (abs(a64) * dxm * dxm + abs(c64) * dym * dym + 2.0 * abs(b64) * dxm * dym)


@njit(inline="always", **_OPTS)
def _axis_range(m, own, other, b, thr, err, start, n):
    """Indices [lo, hi] of 0..n-1 along one axis (start: the tile's first pixel on it, m: the
    Gaussian's centre on it) where `col_range` can return columns, for the conic's coefficient `own`
    of this axis and `other` of the other one: every index outside |d| <= sqrt(2 (err - thr) /
    (own - b^2 / other)) (widened by one for the rounding of d) gets none."""
    b64 = np.float64(b)
    other64 = np.float64(other)
    if not (other64 > 0.0):
        return 0, n - 1
    q = np.float64(own) - b64 * b64 / other64
    if not (q > 0.0):
        return 0, n - 1
    room = (err - np.float64(thr)) * 1.000001 + 1e-9 * abs(np.float64(thr)) + 1e-30
    if not (room >= 0.0):
        return 1, 0
    half = np.sqrt(2.0 * room / q) * 1.000001 + 1.0
    return _span(np.float64(m) - 0.5 - start, half, n)     # centre: where d = 0


@njit(inline="always", **_OPTS)
def row_range(my, mx, a, b, c, thr, xa, ya, tw, th):
    """Rows [r_lo, r_hi] of a tile where `col_range` can return columns (r_lo > r_hi: none).

    A bound on `col_range`'s own test, taken once per (tile, Gaussian) instead of once per row:
    over a row the largest exponent is -dy^2 (c - b^2 / a) / 2, and `col_range`'s error allowance
    is at most its value at the tile's farthest column and row, so every row outside
    |dy| <= sqrt(2 (allowance - thr) / (c - b^2 / a)) (widened by one row for the rounding of dy)
    gets no columns from `col_range` anyway.
    """
    return _axis_range(my, c, a, b, thr, _allowance(my, mx, a, b, c, xa, ya, tw, th), ya, th)


@njit(inline="always", **_OPTS)
def col_bound(my, mx, a, b, c, thr, xa, ya, tw, th):
    """Columns [i_lo, i_hi] of a tile where `col_range` can return columns in some row (i_lo > i_hi:
    none), from one square root per (tile, Gaussian): the half rows of a tile the Gaussian cannot reach.

    `row_range` with the axes swapped. Over all rows, the columns `col_range` returns lie within
    max over dy of (|b dy / a| + sqrt(2 slack(dy) / a)) + 1 of mx, and that maximum (Cauchy-Schwarz)
    is sqrt(2 (allowance - thr) / (a - b^2 / c)), the allowance taken at the tile's farthest column
    and row as in `row_range`.
    """
    return _axis_range(mx, a, c, b, thr, _allowance(my, mx, a, b, c, xa, ya, tw, th), xa, tw)


@njit(inline="always", **_OPTS)
def tight_rows(r_lo, r_hi, my, mx, a, b, c, thr, xa, ya, tw, pyc):
    """[r_lo, r_hi] narrowed from both ends to the first and last rows where `col_range` gives columns.

    `row_range` bounds the Gaussian's rows over the whole tile width, so at a tile beside the
    Gaussian most of its rows are empty. The region in the tile is convex, so the rows between are
    rarely empty; an empty one is walked with every lane masked, which gives the same result as
    skipping it.
    """
    while r_lo <= r_hi:
        i_lo, i_hi = col_range(pyc[ya + r_lo] - my, mx, a, b, c, thr, xa, tw)
        if i_lo <= i_hi:
            break
        r_lo += 1
    while r_hi > r_lo:
        i_lo, i_hi = col_range(pyc[ya + r_hi] - my, mx, a, b, c, thr, xa, tw)
        if i_lo <= i_hi:
            break
        r_hi -= 1
    return r_lo, r_hi
