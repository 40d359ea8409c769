"""The `cpu` backend's one-pass glue against the numpy it replaced: `_pack` (the kernels' inputs in
depth order), `_scatter_grads` (the raster's gradient rows to the outputs), `_camera_points` (camera
points and projected centres), `_deinterleave` and `_interleave` (the channel split and join)."""
from __future__ import annotations

import numpy as np
import pytest

from gsbench.render import cpu_backend as CB
from gsbench.render import cpu_kernels as K
from gsbench.render import cpu_projection as P
from gsbench.render import rules
from gsbench.render.cpu_binning import depth_order


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_pack_equals_the_numpy_gathers(dtype):
    rng = np.random.default_rng(1)
    m, n_ch = 3001, 7
    md = (rng.random((m, 2)) * 300 - 20).astype(dtype)
    conics = rng.random((m, 3)).astype(dtype)
    op = rng.random(m).astype(dtype)
    op[:6] = (0.0, rules.ALPHA_MIN, 1.0, np.finfo(dtype).tiny, 0.5, np.nan)   # at and below the floor, NaN
    ch = rng.standard_normal((m, n_ch)).astype(dtype)
    radii = rng.integers(0, 4000, (m, 2))
    z = rng.random(m).astype(dtype)
    order = depth_order(z)
    gp = np.full((m, K.NPARAM), np.nan, dtype)
    ch_s = np.empty_like(ch)
    boxes = np.empty((4, m), dtype)
    CB._pack(order, md, conics, op, radii, ch, rules.ALPHA_MIN, CB.SKIP_MARGIN, gp, ch_s, boxes)

    mo, ro = md[order], radii[order].astype(dtype)
    assert np.array_equal(gp[:, K.MX:K.MY + 1], mo)
    assert np.array_equal(gp[:, K.CA:K.CC + 1], conics[order])
    assert np.array_equal(gp[:, K.OP], op[order], equal_nan=True)
    thr = np.log(rules.ALPHA_MIN / np.maximum(op[order].astype(np.float64), rules.ALPHA_MIN)) - CB.SKIP_MARGIN
    # numba's and numpy's float64 log may differ in the last bit, so THR (a bound with a 1e-3 margin)
    # may round one ulp of the working dtype apart
    want = thr.astype(dtype)
    nan = np.isnan(want)
    assert nan.sum() == 1 and np.array_equal(np.isnan(gp[:, K.THR]), nan)
    assert np.all(np.abs(gp[~nan, K.THR] - want[~nan]) <= np.spacing(np.abs(want[~nan])))
    assert np.all(gp[:, K.THR + 1:] == 0)
    assert np.array_equal(ch_s, ch[order])
    for got, want in zip(boxes, (mo[:, 0] - ro[:, 0], mo[:, 0] + ro[:, 0], mo[:, 1] - ro[:, 1], mo[:, 1] + ro[:, 1])):
        assert got.dtype == want.dtype and np.array_equal(got, want)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("n_feat", [0, 3])
def test_scatter_grads_equals_the_numpy_assignments(dtype, n_feat):
    rng = np.random.default_rng(2)
    n, m = 500, 321
    ids = np.sort(rng.choice(n, m, replace=False))
    full = rng.standard_normal((m, K.G_CH + 4 + n_feat)).astype(dtype)
    g_rgb = np.zeros((m, 3), dtype)
    g_feat = np.zeros((n, n_feat), dtype)
    g_m2d = np.zeros((n, 2), dtype)
    gr = np.full((m, P.NPROJ), np.nan)
    CB._scatter_grads(full, ids, g_rgb, g_feat, g_m2d, gr)

    assert np.array_equal(g_rgb, full[:, K.G_CH:K.G_CH + 3])
    want_feat = np.zeros((n, n_feat), dtype)
    want_feat[ids] = full[:, K.G_CH + 4:]
    assert np.array_equal(g_feat, want_feat)
    want_m2d = np.zeros((n, 2), dtype)
    want_m2d[ids] = full[:, K.G_MX:K.G_MY + 1]
    assert np.array_equal(g_m2d, want_m2d)
    assert np.array_equal(gr[:, P.P_U:P.P_V + 1], full[:, K.G_MX:K.G_MY + 1])
    assert np.array_equal(gr[:, P.P_CA:P.P_CC + 1], full[:, K.G_CA:K.G_CC + 1])
    assert np.array_equal(gr[:, P.P_OP], full[:, K.G_OP])
    assert np.array_equal(gr[:, P.P_Z], full[:, K.G_CH + 3])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_camera_points_equal_the_numpy_operations(dtype):
    rng = np.random.default_rng(2)
    n = 4000
    m = (rng.standard_normal((n, 3)) * 3).astype(dtype)
    m[0] = np.nan
    m[1] = (np.inf, 0.0, 1.0)
    R = np.linalg.qr(rng.standard_normal((3, 3)))[0].astype(dtype)
    t = rng.standard_normal(3).astype(dtype)
    m[2] = np.linalg.solve(R.astype(np.float64), -t.astype(np.float64)).astype(dtype)   # z near 0
    K_ = np.array([[300.5, 0, 128.25], [0, 310.0, 96.5], [0, 0, 1]], dtype)
    mc = np.empty((n, 3), dtype)
    for r in range(3):
        mc[:, r] = ((m[:, 0] * R[r, 0] + m[:, 1] * R[r, 1]) + m[:, 2] * R[r, 2]) + t[r]
    with np.errstate(all="ignore"):
        zs = np.where(mc[:, 2] != 0, mc[:, 2], dtype(1.0))
        uv = np.stack([K_[0, 0] * mc[:, 0] / zs + K_[0, 2], K_[1, 1] * mc[:, 1] / zs + K_[1, 2]], -1)
    pc, uv2 = np.empty((n, 3)), np.empty((n, 2))
    CB._camera_points(m, R, t, K_, dtype(1.0), pc, uv2)
    assert np.array_equal(pc, mc.astype(np.float64), equal_nan=True)
    assert np.array_equal(uv2, uv.astype(np.float64), equal_nan=True)


@pytest.mark.parametrize("n_feat", [0, 3])
def test_channel_split_and_join_equal_the_slices(n_feat):
    rng = np.random.default_rng(3)
    out = rng.standard_normal((5, 7, 4 + n_feat)).astype(np.float32)
    rgb, depth = np.empty((5, 7, 3), np.float32), np.empty((5, 7), np.float32)
    feat = np.empty((5, 7, n_feat), np.float32)
    CB._deinterleave(out, rgb, depth, feat)
    assert np.array_equal(rgb, out[..., :3]) and np.array_equal(depth, out[..., 3])
    assert np.array_equal(feat, out[..., 4:])
    g = np.full_like(out, np.nan)
    CB._interleave(rgb, depth, feat, g)
    assert np.array_equal(g, out)
    g = np.full_like(out, np.nan)
    CB._interleave(np.zeros((0, 0, 0), np.float32), depth, feat, g)      # a missing part is zero
    assert np.all(g[..., :3] == 0) and np.array_equal(g[..., 3:], out[..., 3:])
