"""Intervals of the report: paired and Welch t intervals against hand-computed values with tabulated
t quantiles (not scipy), the exact MDE against statsmodels' values, Fisher-z interval of Pearson r,
one-seed and extreme cases."""
from __future__ import annotations

import math

import numpy as np
import pytest

from gsbench.reports.stats import compare, mde_r, pearson, pearson_interval

# two-sided 95 % quantiles of Student's t from a printed table
T_TABLE = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776}
# one-sided 80 % quantiles (t_{0.20} column of the same table)
T80_TABLE = {2: 1.061, 3: 0.978, 4: 0.941}


def test_mde_paired_exact():
    # differences 1, 2, 3: sd_diff = 1, n = 3. Exact noncentral t: 3.2640 (statsmodels TTestPower, nobs 3);
    # the normal-shift sum of quantiles (4.303 + 1.061) / sqrt(3) = 3.0969 is 5 % short of it
    d = compare({0: 11.0, 1: 12.0, 2: 13.0}, {0: 10.0, 1: 10.0, 2: 10.0})
    assert d.method == "paired"
    assert d.mde == pytest.approx(3.2640, rel=1e-4)
    assert d.mde > (T_TABLE[2] + T80_TABLE[2]) / math.sqrt(3) * 1.05


def test_mde_welch_exact():
    # sd 1 on both sides, n = 3 each, unpaired: Welch df = 4 = the pooled df, so the exact MDE is
    # statsmodels TTestIndPower's effect size at nobs1 = 3, ratio 1: 3.0709 (times sd = 1)
    d = compare({0: 1.0, 1: 2.0, 2: 3.0}, {3: 3.0, 4: 4.0, 5: 5.0})
    assert d.method == "welch" and d.mde == pytest.approx(3.0709, rel=1e-4)


def test_mde_needs_two_values_and_pearson_mde():
    assert compare({0: 1.0}, {0: 0.5}).mde is None  # one seed: no spread, no MDE (never zero)
    assert compare({0: 1.0, 1: 2.0}, {5: 1.0}).mde is None
    assert compare({0: 2.0, 1: 3.0}, {0: 1.0, 1: 2.0}).mde == 0.0  # identical differences: exact, MDE 0
    # r at n = 12: tanh((1.960 + 0.8416) / sqrt(9)) = tanh(0.93387) = 0.7324
    assert mde_r(12) == pytest.approx(0.7324, abs=2e-4)
    assert mde_r(3) is None


def test_paired_interval_matches_hand_computation():
    row = {0: 10.0, 1: 12.0, 2: 11.0}
    ref = {0: 9.0, 1: 10.0, 2: 10.5}
    d = compare(row, ref)
    assert d.method == "paired" and d.n_a == 3
    diffs = np.array([1.0, 2.0, 0.5])  # row - ref per seed
    half = T_TABLE[2] * diffs.std(ddof=1) / math.sqrt(3)
    assert d.delta == pytest.approx(diffs.mean(), abs=1e-12)
    assert (d.hi - d.lo) / 2.0 == pytest.approx(half, rel=2e-4)  # table has 3 decimals
    assert (d.hi + d.lo) / 2.0 == pytest.approx(diffs.mean(), abs=1e-12)
    assert d.lo < 0.0 < d.hi and not d.significant  # 1.17 +- 1.90 includes zero
    assert d.text(2).startswith("+1.17 [-0.73, +3.06]") and "*" not in d.text(2)


def test_paired_removes_the_shared_seed_noise():
    # the seeds move both rows alike; the row is always 1.0 above: a tight interval that excludes 0
    row = {0: 11.0, 1: 16.0, 2: 21.5}
    ref = {0: 10.0, 1: 15.1, 2: 20.4}
    d = compare(row, ref)
    assert d.significant and d.lo > 0.0
    assert d.text(2).endswith("* (n=3, paired)")
    # unpaired (different seeds) the same numbers are not distinguishable from noise
    w = compare(row, {3: 10.0, 4: 15.1, 5: 20.4})
    assert w.method == "welch" and not w.significant


def test_welch_equal_sizes_equal_variances_has_2n_minus_2_dof():
    row = {0: 1.0, 1: 2.0, 2: 3.0}
    ref = {3: 3.0, 4: 4.0, 5: 5.0}
    d = compare(row, ref)
    assert d.method == "welch"
    half = T_TABLE[4] * math.sqrt(1.0 / 3.0 + 1.0 / 3.0)  # var 1 on each side, n = 3, dof = 4
    assert d.delta == pytest.approx(-2.0)
    assert (d.hi - d.lo) / 2.0 == pytest.approx(half, rel=2e-4) and (d.hi + d.lo) / 2.0 == pytest.approx(-2.0)
    assert d.text(1) == "-2.0 [-4.3, +0.3] (n=3 vs 3)"


def test_welch_unequal_variances_against_float64_formula():
    row = {0: 1.0, 1: 2.0, 2: 3.0, 3: 6.0}
    ref = {10: 2.0, 11: 2.5}
    d = compare(row, ref)
    xa, xb = np.array([1.0, 2.0, 3.0, 6.0]), np.array([2.0, 2.5])
    va, vb = xa.var(ddof=1) / 4, xb.var(ddof=1) / 2
    dof = (va + vb) ** 2 / (va ** 2 / 3 + vb ** 2 / 1)
    assert 3.0 < dof < 4.0
    # the quantile lies between the tabulated values for 3 and 4 degrees of freedom
    half = (d.hi - d.lo) / 2.0
    assert T_TABLE[4] * math.sqrt(va + vb) < half < T_TABLE[3] * math.sqrt(va + vb)


def test_one_seed_is_na_never_zero_width():
    d = compare({0: 5.0}, {0: 4.0})
    assert d.delta == pytest.approx(1.0) and not d.has_interval and not d.significant
    assert d.text(2) == "+1.00 [n/a: one seed] (n=1, paired)"
    d = compare({0: 5.0, 1: 6.0}, {7: 4.0})  # Welch with one reference run
    assert not d.has_interval and d.reason == "one seed"
    assert compare({}, {0: 1.0}).text(2) == "n/a (no value)"
    assert compare({0: 1.0}, {0: math.nan}).text(2) == "n/a (no reference value)"


def test_identical_seeds_give_exact_zero_spread():
    d = compare({0: 2.0, 1: 3.0}, {0: 1.0, 1: 2.0})
    assert d.lo == pytest.approx(1.0) and d.hi == pytest.approx(1.0) and d.significant


def test_extreme_values_do_not_overflow():
    big = 1.5e308
    d = compare({0: big, 1: big * 0.9, 2: big * 0.8}, {0: big * 0.5, 1: big * 0.4, 2: big * 0.3})
    assert d.delta == pytest.approx(0.5 * big, rel=1e-12) and math.isfinite(d.lo) and math.isfinite(d.hi)
    assert d.lo == pytest.approx(0.5 * big, rel=1e-9)  # every paired difference is 0.5 * big
    w = compare({0: big, 1: big * 0.9, 2: big * 0.8}, {5: 0.0, 6: 1.0, 7: 2.0})
    assert w.method == "welch" and w.has_interval and math.isfinite(w.hi - w.lo)
    assert w.delta == pytest.approx(0.9 * big, rel=1e-12)
    # a spread beyond float64 is reported as such, not as an infinite interval
    assert compare({0: big, 1: -big}, {5: 0.0, 6: 1.0}).reason == "difference overflows float64"
    o = compare({0: big, 1: big}, {0: -big, 1: -big})
    assert o.delta is None and o.reason == "difference overflows float64"
    tiny = compare({0: 3e-320, 1: 5e-320}, {0: 1e-320, 1: 2e-320})
    assert tiny.delta == pytest.approx(2.5e-320, rel=0.05) and tiny.has_interval


def test_pearson_interval_fisher_z():
    lo, hi = pearson_interval(0.5, 12)
    z, half = math.atanh(0.5), 1.96 / 3.0  # 1.96 = tabulated normal quantile
    assert lo == pytest.approx(math.tanh(z - half), abs=1e-4) and hi == pytest.approx(math.tanh(z + half), abs=1e-4)
    assert pearson_interval(0.9, 3) is None
    lo, hi = pearson_interval(1.0, 10)  # |r| = 1: finite, degenerate at the boundary
    assert math.isfinite(lo) and hi == pytest.approx(1.0)
    r, why = pearson([1, 2, 3, 4], [2, 4, 6, 8.5])
    assert why is None and 0.99 < r <= 1.0
    assert pearson([1, 1, 1], [1, 2, 3]) == (None, "lambda constant")


def test_tiny_differences_get_enough_decimals():
    d = compare({0: 1.0031, 1: 2.0030, 2: 3.0032}, {0: 1.0, 1: 2.0, 2: 3.0})
    assert d.significant
    # half-width ~2.5e-4: four decimals at least, never "+0.00 [+0.00, +0.00] *"
    assert d.text(2).startswith("+0.00310 [+0.00") and d.text(2).endswith("* (n=3, paired)")
    assert compare({0: 1.0, 1: 2.0}, {0: 1.0, 1: 2.0}).text(2) == "+0.00 [+0.00, +0.00] (n=2, paired)"
