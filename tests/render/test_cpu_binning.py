"""`depth_order`, the `cpu` rasterizer's radix argsort, against numpy's stable argsort."""
from __future__ import annotations

import numpy as np
import pytest

from gsbench.render.cpu_binning import depth_order


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
