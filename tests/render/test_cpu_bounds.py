"""The `cpu` rasterizer's footprint bounds against brute force: every pixel of a tile whose computed
exponent reaches a Gaussian's THR (the only pixels the kernels may not skip) lies inside the rows
and columns the bounds give, for round, elongated, tiny and huge Gaussians in float32 and float64."""
from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from gsbench.render.cpu_bounds import col_bound, row_range
from gsbench.render.cpu_kernels import HALF, _half_rows


@njit(cache=False)
def _bounds(g, xa, ya, tw, th, spans):
    my, mx, a, b, c, thr = g[0], g[1], g[2], g[3], g[4], g[5]
    r = row_range(my, mx, a, b, c, thr, xa, ya, tw, th)
    k = col_bound(my, mx, a, b, c, thr, xa, ya, tw, th)
    rows = _half_rows(my, mx, a, b, c, thr, xa, ya, tw, th)
    for i in range(4):
        spans[i] = rows[i]
    return r[0], r[1], k[0], k[1]


def _gaussians(rng, n: int, dtype) -> np.ndarray:
    """(n, 6) rows my, mx, a, b, c, thr around a 16x16 tile at (32, 48): conics of random axes
    (0.2 to 40 px) and angles, thresholds from opacities 1/255 to 1."""
    out = np.empty((n, 6), dtype)
    for k in range(n):
        s1, s2 = np.exp(rng.uniform(np.log(0.2), np.log(40.0), 2))
        t = rng.uniform(0, np.pi)
        R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        conic = np.linalg.inv(R @ np.diag([s1 * s1, s2 * s2]) @ R.T)
        op = np.exp(rng.uniform(np.log(1 / 255), 0.0))
        thr = np.log((1 / 255) / max(op, 1 / 255)) - 1e-3
        out[k] = (rng.uniform(48 - 30, 48 + 46), rng.uniform(32 - 30, 32 + 46),
                  conic[0, 0], conic[0, 1], conic[1, 1], thr)
    return out


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("tw,th", [(16, 16), (11, 7), (5, 16)])
def test_bounds_hold_every_pixel_that_reaches_thr(dtype, tw, th):
    rng = np.random.default_rng(3)
    xa, ya = 32, 48
    pxc = np.arange(xa + 16, dtype=dtype) + dtype(0.5)
    pyc = np.arange(ya + 16, dtype=dtype) + dtype(0.5)
    spans = np.empty(4, np.int8)
    reached = 0
    for g in _gaussians(rng, 1200, dtype):
        my, mx, a, b, c, thr = g
        dx = pxc[xa:xa + tw][None, :] - mx
        dy = pyc[ya:ya + th][:, None] - my
        power = dtype(-0.5) * (a * dx * dx + c * dy * dy) - b * dx * dy     # as the kernels compute it
        hit = power >= thr
        r_lo, r_hi, k_lo, k_hi = _bounds(g, xa, ya, tw, th, spans)
        rows, cols = np.nonzero(hit)
        reached += rows.size > 0
        assert np.all((rows >= r_lo) & (rows <= r_hi)), "row_range misses a pixel"
        assert np.all((cols >= k_lo) & (cols <= k_hi)), "col_bound misses a pixel"
        for h in range(2):
            in_half = (cols >= h * HALF) & (cols < (h + 1) * HALF)
            assert np.all((rows[in_half] >= spans[2 * h]) & (rows[in_half] <= spans[2 * h + 1])), \
                f"half {h}'s rows miss a pixel"
    assert reached > 120           # the sample reaches the tile often enough to mean something
