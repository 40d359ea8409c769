"""The `cpu` rasterizer's footprint bounds against brute force: every pixel whose computed exponent
reaches a Gaussian's THR (the only pixels the kernels may not skip) lies inside the Gaussian's box
and inside the rows of each tile half that `_half_rows` gives, for round, elongated, tiny and huge
Gaussians in float32 and float64; and the boxes are no wider than the float64 ellipse and the documented margins."""
from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from gsbench.render import cpu_bounds as B
from gsbench.render import cpu_kernels as K


@njit(cache=False)
def _gaussian_boxes(gp, boxes):
    """boxes[k] = `cpu_bounds.box` of row k of gp, as the backend's `_pack` computes each row's."""
    for k in range(gp.shape[0]):
        boxes[k, B.E_CX], boxes[k, B.E_CY], boxes[k, B.E_HX], boxes[k, B.E_HY] = B.box(
            gp[k, K.MX], gp[k, K.MY], gp[k, K.CA], gp[k, K.CB], gp[k, K.CC], gp[k, K.THR])


@njit(cache=False)
def _tile_halves(boxes, g, xa, ya, tw, th, out):
    r = K._half_rows(boxes, g, xa, ya, tw, th)
    for i in range(4):
        out[i] = r[i]


def _gaussians(rng, n: int, dtype, max_ratio: float = 200.0) -> np.ndarray:
    """(n, NPARAM) kernel rows: centres around (40, 56), conics of random axes (0.2 to 40 px, at most
    max_ratio apart) and angles, THR from opacities 1/255 to 1 as the backend computes it."""
    gp = np.zeros((n, K.NPARAM), dtype)
    for k in range(n):
        s1 = np.exp(rng.uniform(np.log(0.2), np.log(40.0)))
        s2 = np.clip(np.exp(rng.uniform(np.log(0.2), np.log(40.0))), s1 / max_ratio, s1 * max_ratio)
        t = rng.uniform(0, np.pi)
        R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        conic = np.linalg.inv(R @ np.diag([s1 * s1, s2 * s2]) @ R.T)
        op = np.exp(rng.uniform(np.log(1 / 255), 0.0))
        gp[k, K.MX], gp[k, K.MY] = rng.uniform(10, 70), rng.uniform(26, 86)
        gp[k, K.CA], gp[k, K.CB], gp[k, K.CC] = conic[0, 0], conic[0, 1], conic[1, 1]
        gp[k, K.OP] = op
        gp[k, K.THR] = np.log((1 / 255) / max(op, 1 / 255)) - 1e-3
    return gp


def _reached(g, dtype, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """(len(ys), len(xs)) bool: the computed exponent >= THR, as the kernels compute it."""
    dx = (xs.astype(dtype) + dtype(0.5))[None, :] - g[K.MX]
    dy = (ys.astype(dtype) + dtype(0.5))[:, None] - g[K.MY]
    power = dtype(-0.5) * (g[K.CA] * dx * dx + g[K.CC] * dy * dy) - g[K.CB] * dx * dy
    return power >= g[K.THR]


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_every_pixel_that_reaches_thr_is_in_the_box_and_the_tile_halves(dtype):
    rng = np.random.default_rng(3)
    gp = _gaussians(rng, 1500, dtype)
    boxes = np.empty((gp.shape[0], B.NBOX))
    _gaussian_boxes(gp, boxes)
    xs, ys = np.arange(-80, 160), np.arange(-60, 180)
    halves = np.empty(4, np.int64)
    n_hit = 0
    for k, g in enumerate(gp):
        cx, cy, hx, hy = boxes[k]
        assert np.isfinite(hx) and np.isfinite(hy), "a well-conditioned conic got no bound"
        hit = _reached(g, dtype, xs, ys)
        rows, cols = np.nonzero(hit)
        n_hit += rows.size > 0
        assert np.all(np.abs(xs[cols] - cx) <= hx) and np.all(np.abs(ys[rows] - cy) <= hy), f"Gaussian {k}"
        # the box is tight: the ellipse Q <= -2 THR's extents in float64, widened only as documented
        # (1 / sqrt(1 - 2e-5 kappa) for the rounding argument, 1e-6 relative, 1e-3 px)
        a, b, c, t = (np.float64(g[i]) for i in (K.CA, K.CB, K.CC, K.THR))
        det = a * c - b * b
        widen = 1.0 / np.sqrt(1.0 - 2e-5 * (np.sqrt(a * c) + abs(b)) ** 2 / det)
        assert hx <= np.sqrt(-2 * t * c / det) * widen * 1.000002 + 1.001e-3
        assert hy <= np.sqrt(-2 * t * a / det) * widen * 1.000002 + 1.001e-3
        for xa, ya, tw, th in ((32, 48, 16, 16), (32, 48, 11, 7), (48, 64, 5, 16)):
            _tile_halves(boxes, k, xa, ya, tw, th, halves)
            sub = hit[ya + 60:ya + 60 + th, xa + 80:xa + 80 + tw]
            r, c = np.nonzero(sub)
            for h in range(2):
                in_half = (c >= h * K.HALF) & (c < (h + 1) * K.HALF)
                assert np.all((r[in_half] >= halves[2 * h]) & (r[in_half] <= halves[2 * h + 1])), \
                    f"Gaussian {k}, tile ({xa}, {ya}) {tw}x{th}: half {h}'s rows miss a pixel"
    assert n_hit > 1000


def test_box_matches_the_float64_ellipse_and_its_special_cases():
    """The half-widths against the ellipse's exact extents in float64 (sqrt(-2 THR c / det)), and the
    cases with no bound (inf) or no pixel (-1)."""
    gp = np.zeros((7, K.NPARAM), np.float32)
    gp[:, K.MX], gp[:, K.MY] = 10.25, 20.75
    gp[:, K.CA], gp[:, K.CB], gp[:, K.CC] = 0.5, 0.1, 0.25
    gp[:, K.THR] = -5.0
    gp[1, K.THR] = 0.5                               # opacity below ALPHA_MIN: THR > 0
    gp[2, K.MX] = np.nan
    gp[3, K.CB] = 0.5                                # det < 0: not positive definite
    gp[4, K.CA], gp[4, K.CB], gp[4, K.CC] = 1.0, 0.99999, 1.0    # kappa ~ 2e5: beyond the argument
    gp[5, K.THR] = np.nan
    gp[6, K.CA], gp[6, K.CB], gp[6, K.CC] = 1e30, 0.0, 1e-30     # extreme but positive definite
    boxes = np.empty((7, B.NBOX))
    _gaussian_boxes(gp, boxes)
    a, b, c = 0.5, 0.1, 0.25
    det = a * c - b * b
    assert boxes[0, 0] == 9.75 and boxes[0, 1] == 20.25
    assert boxes[0, 2] == pytest.approx(np.sqrt(10.0 * c / det), rel=1e-3)
    assert boxes[0, 3] == pytest.approx(np.sqrt(10.0 * a / det), rel=1e-3)
    for k in (1, 2, 5):
        assert tuple(boxes[k]) == (0.0, 0.0, -1.0, -1.0)
    for k in (3, 4):
        assert np.isinf(boxes[k, 2]) and np.isinf(boxes[k, 3])
    assert boxes[6, 2] == pytest.approx(np.sqrt(10.0 / 1e30) * 1.000001 + 1e-3, rel=1e-6) and boxes[6, 3] > 1e15
    halves = np.empty(4, np.int64)
    for k, want_none in ((1, True), (2, True), (3, False), (4, False), (6, True)):
        _tile_halves(boxes, k, 0, 16, 16, 16, halves)
        none = halves[0] > halves[1] and halves[2] > halves[3]
        assert none == want_none, k
