"""`depth_order`, the `cpu` rasterizer's radix argsort, against numpy's stable argsort; `bin_tiles`
against a brute-force listing with the reference's box test, for 1, 2 and 7 workers."""
from __future__ import annotations

import numpy as np
import pytest

from gsbench.render.cpu_binning import bin_tiles, depth_order


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("n", [0, 1, 2, 7, 15_000])
def test_equals_numpys_stable_argsort(dtype, n):
    rng = np.random.default_rng(n)
    z = (rng.standard_normal(n) * 3).astype(dtype)
    if n >= 15:
        z[::7] = z[3]                                  # ties: index order decides
        z[[1, 4]] = (0.0, -0.0)                        # the two zeros tie
        z[[5, 13]] = np.nan                            # NaN last, in index order
        z[[11, 12]] = (np.inf, -np.inf)
        z[14] = np.finfo(dtype).tiny / 4               # subnormal
    got = depth_order(z)
    assert np.array_equal(got, np.argsort(z, kind="stable"))


def test_other_dtypes_are_refused():
    with pytest.raises(ValueError, match="float32 or float64"):
        depth_order(np.arange(4, dtype=np.int32))


def _brute_lists(x0, x1, y0, y1, width, height, ts):
    """Per tile, the ranks whose box [x0, x1] x [y0, y1] meets the tile's pixel span [t ts, min(size,
    (t + 1) ts)] on both axes (the reference's test), in rank order."""
    out = []
    for ty in range((height + ts - 1) // ts):
        for tx in range((width + ts - 1) // ts):
            xa, xb = tx * ts, min(width, (tx + 1) * ts)
            ya, yb = ty * ts, min(height, (ty + 1) * ts)
            hit = (x1 >= xa) & (x0 <= xb) & (y1 >= ya) & (y0 <= yb)
            out.append(np.flatnonzero(hit))
    return out


@pytest.mark.parametrize("n", [0, 1, 3, 2_000])
@pytest.mark.parametrize("n_workers", [1, 2, 7])
def test_bin_tiles_lists_every_meeting_box_in_rank_order(n, n_workers):
    rng = np.random.default_rng(n)
    x, y = rng.uniform(-60, 160, n).astype(np.float32), rng.uniform(-60, 130, n).astype(np.float32)
    r = np.exp(rng.uniform(-3, 4, n)).astype(np.float32)
    if n > 10:
        r[0] = np.inf                                # a box over everything
        x[1] = np.nan                                # a NaN box meets no tile
    x0, x1, y0, y1 = x - r, x + r, y - r, y + r
    tile_off, ranks = bin_tiles(x0, x1, y0, y1, 100, 70, 16, n_workers)
    want = _brute_lists(x0, x1, y0, y1, 100, 70, 16)
    assert tile_off.size == len(want) + 1 and tile_off[0] == 0
    for t, w in enumerate(want):
        assert np.array_equal(ranks[tile_off[t]:tile_off[t + 1]], w), f"tile {t}"
