"""The `cpu` backend's one-pass glue against the numpy it replaced: `_pack` (the kernels' inputs in
depth order), `_scatter_grads` (the raster's gradient rows to the outputs), `_camera_points` (camera
points and projected centres), and the kernels' three outputs (rgb, depth, features) against one."""
from __future__ import annotations

import numpy as np
import pytest

from gsbench.render import cpu_backend as CB
from gsbench.render import cpu_bounds as B
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
    reach = np.empty((m, B.NBOX))
    CB._pack(order, md, conics, op, radii, ch, rules.ALPHA_MIN, CB.SKIP_MARGIN, gp, ch_s, boxes, reach)

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
    for k in (0, 1, 5, 100, m - 1):      # each row's reach box is cpu_bounds.box of the packed row
        want = B.box.py_func(*(np.float64(gp[k, i]) for i in (K.MX, K.MY, K.CA, K.CB, K.CC, K.THR)))
        assert np.array_equal(reach[k], np.array(want), equal_nan=True)


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
def test_split_outputs_equal_the_slices_of_one_output(n_feat):
    """The kernels write rgb, depth and features to three arrays (and read their gradients so):
    the same bits as one (H, W, C) output sliced, forward and backward."""
    rng = np.random.default_rng(3)
    m, w, h = 400, 45, 37
    md = np.stack([rng.random(m) * w, rng.random(m) * h], 1).astype(np.float32)
    s = (rng.random(m) * 2 + 0.3).astype(np.float32)
    conics = np.stack([1 / s**2, (rng.random(m) - 0.5) * 0.1, 1 / s**2], 1).astype(np.float32)
    op = rng.random(m).astype(np.float32)
    ch = rng.standard_normal((m, 4 + n_feat)).astype(np.float32)
    radii = np.full((m, 2), 8, np.int64)
    z = rng.random(m).astype(np.float32)
    one, t1, st1 = CB._raster_forward(md, conics, op, ch, radii, z, w, h, 16)
    (rgb, depth, feat), t3, st3 = CB._raster_forward(md, conics, op, ch, radii, z, w, h, 16, split=(3, 1))
    out = one[0]
    assert one[1].shape == one[2].shape == (h, w, 0)
    assert np.array_equal(rgb, out[..., :3]) and np.array_equal(depth[..., 0], out[..., 3])
    assert np.array_equal(feat, out[..., 4:]) and np.array_equal(t1, t3)
    g = rng.standard_normal(out.shape).astype(np.float32)
    g_t = rng.standard_normal((h, w)).astype(np.float32)
    none = np.zeros((h, w, 0), np.float32)
    rows1 = CB._raster_backward(st1, (g, none, none), g_t)
    rows3 = CB._raster_backward(st3, (np.ascontiguousarray(g[..., :3]), np.ascontiguousarray(g[..., 3:4]),
                                      np.ascontiguousarray(g[..., 4:])), g_t)
    assert np.array_equal(rows1, rows3) and np.any(rows1 != 0)


def test_reduce_rows_adds_each_gradient_in_row_order():
    """Each element's rows of tiles [5, 31) are added in row order (tile, then depth rank): float32
    sums of values of mixed magnitudes, compared bit for bit with numpy adding row by row."""
    rng = np.random.default_rng(5)
    m, n_cols, n_tiles = 300, 13, 40
    counts = rng.integers(0, 60, n_tiles)
    tile_off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    ranks = rng.integers(0, m, tile_off[-1]).astype(np.int32)
    order = rng.permutation(m).astype(np.int64)
    rows = (rng.standard_normal((tile_off[-1], n_cols)) * 10.0 ** rng.integers(-6, 6, (tile_off[-1], 1))
            ).astype(np.float32)
    want = np.zeros((m, n_cols), np.float32)
    for r in range(tile_off[5], tile_off[31]):          # serial, in row order
        want[order[ranks[r]]] += rows[r - tile_off[5]]
    got = np.zeros((m, n_cols), np.float32)
    K.reduce_rows(tile_off, ranks, order, 5, 31, rows, got)
    assert np.array_equal(got, want)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_visible_rows_and_channels_equal_the_numpy_gathers(dtype):
    """`_visible` (the visible rows, radii and means2d) and `_channels` against the numpy gathers,
    cast and scatter they replaced."""
    rng = np.random.default_rng(6)
    n, d = 700, 3
    ok = rng.random(n) < 0.6
    params = rng.standard_normal((n, P.NPROJ)) * 1e3
    radii = rng.integers(0, 50, (n, 2))
    ids = np.flatnonzero(ok)
    m = ids.size
    prm, rad, m2d = np.empty((m, P.NPROJ), dtype), np.empty((m, 2), np.int64), np.full((n, 2), np.nan, dtype)
    CB._visible(ok, params, radii, prm, rad, m2d)
    assert np.array_equal(prm, params[ids].astype(dtype)) and np.array_equal(rad, radii[ids])
    want = np.zeros((n, 2), dtype)
    want[ids] = params[ids, P.P_U:P.P_V + 1].astype(dtype)
    assert np.array_equal(m2d, want)
    rgb, feat = rng.random((m, 3)).astype(dtype), rng.random((n, d)).astype(dtype)
    ch = np.empty((m, 4 + d), dtype)
    CB._channels(rgb, prm[:, P.P_Z], feat, ids, ch)
    assert np.array_equal(ch, np.concatenate([rgb, prm[:, P.P_Z:P.P_Z + 1], feat[ids]], 1))
