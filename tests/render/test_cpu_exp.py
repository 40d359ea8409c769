"""The `cpu` kernels' exponentials (`_exp` in float64, `_exp32` in float32: polynomials without a
library call) against float64 exp."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from numba import njit

from gsbench.render.cpu_backend import rasterize_cpu
from gsbench.render.cpu_exp import _exp, _exp32, _like
from gsbench.render.projection import Projected


@njit(cache=False)
def _exp64_rounded(x, out):
    for i in range(x.size):
        out[i] = _like(_exp(np.float64(x[i])), x[i])


@njit(cache=False)
def _exp32_all(x, out):
    for i in range(x.size):
        out[i] = _exp32(x[i])


@njit(cache=False)
def _exp64(x, out):
    for i in range(x.size):
        out[i] = _like(_exp(x[i]), x[i])


def _samples() -> np.ndarray:
    rng = np.random.default_rng(0)
    edges = [0.0, -0.0, -1e-30, -1e-7, -0.5 * np.log(2.0), -np.log(2.0), -1.0, -5.54, -87.3, -103.0,
             -104.0, -700.0, -708.0, -709.0, -745.0, -1e4]
    return np.concatenate([edges, -rng.random(200_000) * 20.0, -rng.random(20_000) * 750.0,
                           -np.linspace(0.0, 1e-6, 1000)])


def test_float32_is_the_correctly_rounded_exp():
    x = _samples().astype(np.float32)
    got = np.empty_like(x)
    _exp64_rounded(x, got)
    want = np.exp(x.astype(np.float64)).astype(np.float32)     # float64 exp, rounded once
    assert np.array_equal(got, want), f"{int(np.sum(got != want))} of {x.size} differ"


def _ulp32(v: np.ndarray) -> np.ndarray:
    """The spacing of float32 numbers at v > 0 (normal range), in float64 (np.spacing reads 0 when
    the CPU flushes subnormals)."""
    return np.ldexp(1.0, (np.floor(np.log2(v)) - 23).astype(int))


def test_float32_polynomial_within_one_ulp():
    """`_exp32`, the float32 kernels' exponential: within 1.01 ulp of the exact value (PyTorch's CPU
    expf is specified within 1 ulp); most values are the correctly rounded ones."""
    rng = np.random.default_rng(1)
    x = np.concatenate([_samples(), -rng.random(2_000_000) * 20.0, -rng.random(100_000) * 87.0])
    x = x[x >= -87.0].astype(np.float32)       # below, the clamp holds exp at exp(-87)
    got = np.empty_like(x)
    _exp32_all(x, got)
    want = np.exp(x.astype(np.float64))
    err = np.abs(got.astype(np.float64) - want) / _ulp32(want)
    assert err.max() <= 1.01, f"{err.max():.3f} ulp at x = {x[np.argmax(err)]!r}"
    assert np.mean(got == want.astype(np.float32)) > 0.85


def test_float32_clamped_outside_its_domain():
    x = np.array([0.0, -0.0, 1.0, 50.0, np.inf, -np.inf, np.nan, -88.0, -1e30], np.float32)
    got = np.empty_like(x)
    _exp32_all(x, got)
    assert np.all(np.isfinite(got)) and np.all(got <= 1.0) and np.all(got > 0.0)
    assert got[0] == 1.0 and got[1] == 1.0
    assert abs(float(got[-1]) / np.exp(-87.0) - 1.0) < 2e-7      # exp(-87) within 1 ulp


def test_float64_within_a_few_ulp():
    x = _samples()
    x = x[x >= -700.0]             # below that np.exp is subnormal / 0 and the clamp takes over
    got = np.empty_like(x)
    _exp64(x, got)
    want = np.exp(x)
    rel = np.abs(got - want) / want
    assert rel.max() <= 4 * np.finfo(np.float64).eps


def test_clamped_outside_its_domain():
    """Callers mask every lane whose exponent is > 0 or NaN; the value there only has to be finite."""
    x = np.array([1.0, 50.0, np.inf, -np.inf, np.nan, -1e300])
    got = np.empty_like(x)
    _exp64(x, got)
    assert np.all(np.isfinite(got)) and np.all(got <= 1.0) and np.all(got >= 0.0)


def test_tile_size_above_the_lane_count_is_refused():
    n = 3
    proj = Projected(torch.arange(n), torch.full((n, 2), 4.0), torch.tensor([[1.0, 0.0, 1.0]] * n),
                     torch.full((n,), 2.0), torch.full((n,), 0.5), torch.full((n, 2), 3), torch.zeros(n, 3))
    with pytest.raises(ValueError, match="tile_size"):
        rasterize_cpu(proj, torch.ones(n, 3), 8, 8, tile_size=17)
