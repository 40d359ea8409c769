"""Rigorous bounds of where a Gaussian can pass the `cpu` rasterizer's skip test.

A pixel is skipped when its computed exponent is below the Gaussian's THR (gsbench/render/cpu_kernels.py).
`box` gives, once per Gaussian and render, the half-widths of a box around the Gaussian's centre
outside which no pixel's computed exponent reaches THR; `tile_rows` turns the box into the rows and
columns of one tile. Walking only those gives exactly the result of walking the whole tile.

Why the box holds. With d = (dx, dy) from the centre, the exact exponent is -Q/2, Q = a dx^2 + 2 b dx dy
+ c dy^2 (the conic [[a, b], [b, c]]). The kernels compute it in the working dtype from dx and dy
rounded to it, ten roundings in all, each relative to its own term, so it lies within 1e-5 Q_abs of
-Q/2, Q_abs = a dx^2 + c dy^2 + 2 |b dx dy| (the bound is about 3 * 2^-24 Q_abs in float32: a 50x
margin). For a positive definite conic, Q_abs <= kappa Q with kappa = (sqrt(ac) + |b|)^2 / (ac - b^2)
(|2 b dx dy| <= rho (a dx^2 + c dy^2), rho = |b| / sqrt(ac)). So a pixel that reaches THR has
Q <= Qmax = -2 THR / (1 - 2e-5 kappa), and over the ellipse Q <= Qmax, |dx| <= sqrt(Qmax c / det) and
|dy| <= sqrt(Qmax a / det), det = ac - b^2. In float64, det has a relative error below 1e-15 kappa
(none from the products when the working dtype is float32); that and the other float64 roundings
are covered by the relative 1e-6 and the absolute 1e-3 pixels.
"""
from __future__ import annotations

import numpy as np
from numba import njit

_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)

E_CX, E_CY, E_HX, E_HY = 0, 1, 2, 3      # a box: centre - 0.5 (x, y), half-widths (x, y); float64
NBOX = 4


@njit(inline="always", **_OPTS)
def box(mx, my, a, b, c, thr):
    """(x - 0.5, y - 0.5, hx, hy) in float64 of a Gaussian (centre, conic, THR in the working dtype):
    its centre in pixel-index units (pixel i's centre is i + 0.5) and the half-widths, in pixels, of
    the box outside which its computed exponent cannot reach THR. hx = hy = -1: no pixel can (THR > 0
    or NaN, a non-finite centre); inf: no bound (a conic that is not positive definite, or too
    elongated for the rounding argument, kappa >= 50,000)."""
    x = np.float64(mx)
    y = np.float64(my)
    a = np.float64(a)
    b = np.float64(b)
    c = np.float64(c)
    t = np.float64(thr)
    if not (t <= 0.0 and np.isfinite(x) and np.isfinite(y)):
        return 0.0, 0.0, -1.0, -1.0            # a finite centre: no NaN reaches the float -> int conversion
    det = a * c - b * b
    if a > 0.0 and c > 0.0 and det > 0.0 and np.isfinite(det):
        s = np.sqrt(a * c) + abs(b)
        shrink = 1.0 - 2e-5 * (s * s / det)
        if shrink > 0.0:
            qmax = -2.0 * t / shrink
            return (x - 0.5, y - 0.5, np.sqrt(qmax * c / det) * 1.000001 + 1e-3,
                    np.sqrt(qmax * a / det) * 1.000001 + 1e-3)
    return x - 0.5, y - 0.5, np.inf, np.inf


@njit(inline="always", **_OPTS)
def _span(centre, half, n):
    """Indices [lo, hi] of 0..n-1 within `half` of `centre` (lo > hi: none), clamped before the
    float -> int conversion so that huge or infinite bounds stay in range."""
    lo = min(max(centre - half, -1.0), n + 1.0)
    hi = min(max(centre + half, -1.0), n + 1.0)
    return max(0, int(np.ceil(lo))), min(n - 1, int(np.floor(hi)))


@njit(inline="always", **_OPTS)
def tile_rows(boxes, g, xa, ya, tw, th):
    """(r_lo, r_hi, k_lo, k_hi): the rows and columns of the tile at (xa, ya) of tw x th pixels that
    row g of `boxes` (one `box` per row, (M, NBOX) float64) meets (lo > hi: none)."""
    r_lo, r_hi = _span(boxes[g, E_CY] - ya, boxes[g, E_HY], th)
    k_lo, k_hi = _span(boxes[g, E_CX] - xa, boxes[g, E_HX], tw)
    return r_lo, r_hi, k_lo, k_hi
