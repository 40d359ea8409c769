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
def _allowance(my, mx, a, b, c, xa, ya, tw, th):
    """An upper bound, over the tile, of how far the exponent computed in the working dtype can lie
    from the exact quadratic -(a dx^2 + 2 b dx dy + c dy^2) / 2 (float64): 1e-5 (|a| dx^2 + |c| dy^2 +
    2 |b dx dy|) at the tile's farthest column and row, widened by one pixel for the rounding of dx
    and dy; 30x the float32 rounding bound of the five operations."""
    a64 = np.float64(a)
    b64 = np.float64(b)
    c64 = np.float64(c)
    dxm = max(abs(xa + 0.5 - np.float64(mx)), abs(xa + tw - 0.5 - np.float64(mx))) + 1.0
    dym = max(abs(ya + 0.5 - np.float64(my)), abs(ya + th - 0.5 - np.float64(my))) + 1.0
    return 1e-5 * (abs(a64) * dxm * dxm + abs(c64) * dym * dym + 2.0 * abs(b64) * dxm * dym)


@njit(inline="always", **_OPTS)
def _axis_range(m, own, other, b, thr, err, start, n):
    """Indices [lo, hi] of 0..n-1 along one axis (start: the tile's first pixel on it, m: the
    Gaussian's centre on it) where the computed exponent can reach `thr`, for the conic's coefficient
    `own` of this axis and `other` of the other one. Along a line of constant d on this axis the exact
    exponent peaks at -d^2 (own - b^2 / other) / 2, and the computed one exceeds the exact one by less
    than `err`, so every index outside |d| <= sqrt(2 (err - thr) / (own - b^2 / other)) (widened by
    one for the rounding of d) is below thr everywhere."""
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
    """Rows [r_lo, r_hi] of a tile where the computed exponent can reach `thr` (r_lo > r_hi: none):
    over a row the exact exponent peaks at -dy^2 (c - b^2 / a) / 2, so every row outside
    |dy| <= sqrt(2 (allowance - thr) / (c - b^2 / a)) (`_allowance`; widened by one row for the
    rounding of dy) is below thr in every column. One square root per (tile, Gaussian).
    """
    return _axis_range(my, c, a, b, thr, _allowance(my, mx, a, b, c, xa, ya, tw, th), ya, th)


@njit(inline="always", **_OPTS)
def col_bound(my, mx, a, b, c, thr, xa, ya, tw, th):
    """Columns [i_lo, i_hi] of a tile where the computed exponent can reach `thr` in some row (i_lo >
    i_hi: none): `row_range` with the axes swapped, so the halves of a tile a Gaussian cannot reach
    are skipped. One square root per (tile, Gaussian).
    """
    return _axis_range(mx, a, c, b, thr, _allowance(my, mx, a, b, c, xa, ya, tw, th), xa, tw)
