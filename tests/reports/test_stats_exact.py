"""The report's statistics against scipy and statsmodels on hand cases: paired and Welch intervals and
p-values (scipy.stats.ttest_rel / ttest_ind(equal_var=False)), the exact noncentral-t MDE (statsmodels
TTestPower), Holm (statsmodels multipletests), and pairing on the shared seeds with the dropped ones named."""
from __future__ import annotations

import gc
import math

import numpy as np
import pytest
from scipy import stats as sps
from statsmodels.stats.multitest import multipletests
from statsmodels.stats.power import TTestPower, ttest_power

from gsbench.reports.stats import compare, holm


def _by_seed(values, seeds=None) -> dict:
    return {s: float(v) for s, v in zip(seeds if seeds is not None else range(len(values)), values)}


@pytest.mark.parametrize("n", [2, 3, 4, 6, 10])
def test_paired_mde_is_the_exact_noncentral_t_answer(n):
    rng = np.random.default_rng(n)
    ref = rng.normal(20.0, 1.0, n)
    row = ref + rng.normal(0.3, 0.5, n)
    d = compare(_by_seed(row), _by_seed(ref))
    sd = float(np.std(row - ref, ddof=1))
    effect = TTestPower().solve_power(nobs=n, alpha=0.05, power=0.8, alternative="two-sided")
    assert d.method == "paired" and d.mde == pytest.approx(effect * sd, rel=1e-6)


def test_the_normal_shift_mde_was_too_small_at_two_and_three_seeds():
    # the old rule, (t_{0.975,n-1} + t_{0.80,n-1}) * sd / sqrt(n), against the exact one (the issue: 16 %, 5 %)
    for n, short in ((2, 0.15), (3, 0.05)):
        ref = {s: 10.0 for s in range(n)}
        row = {s: 10.0 + s for s in range(n)}  # differences 0, 1, (2)
        sd = float(np.std(np.arange(n), ddof=1))
        old = (sps.t.ppf(0.975, n - 1) + sps.t.ppf(0.8, n - 1)) * sd / math.sqrt(n)
        assert compare(row, ref).mde > old * (1.0 + short)


def test_welch_mde_has_80_percent_power_at_the_welch_df():
    a, b = [1.0, 2.0, 3.0, 6.0], [2.0, 2.5, 2.2]
    d = compare(_by_seed(a), _by_seed(b, [10, 11, 12]))
    va, vb = np.var(a, ddof=1) / 4, np.var(b, ddof=1) / 3
    se, dof = math.sqrt(va + vb), (va + vb) ** 2 / (va ** 2 / 3 + vb ** 2 / 2)
    assert d.method == "welch" and 3.0 < dof < 4.0
    # statsmodels' power of a t test with noncentrality mde / se (nobs 1) at the Welch-Satterthwaite df
    assert ttest_power(d.mde / se, nobs=1, alpha=0.05, df=dof) == pytest.approx(0.8, abs=1e-6)


def test_intervals_and_p_values_match_scipy():
    rng = np.random.default_rng(7)
    for trial in range(20):
        n = 2 + trial % 5
        shared = rng.normal(0.0, 2.0, n)  # seed noise both rows share
        ref = 20.0 + shared + rng.normal(0.0, 0.4, n)
        row = 20.0 + shared + rng.normal(0.5 * (trial % 3), 0.4, n)
        d = compare(_by_seed(row), _by_seed(ref))
        t = sps.ttest_rel(row, ref)
        lo, hi = t.confidence_interval(0.95)
        assert d.method == "paired" and d.p == pytest.approx(t.pvalue, rel=1e-9, abs=1e-15)
        assert (d.lo, d.hi) == (pytest.approx(lo, rel=1e-9), pytest.approx(hi, rel=1e-9))
        assert d.significant == (t.pvalue < 0.05)
        other = rng.normal(21.0, 1.0, n + 1)
        w = compare(_by_seed(row), _by_seed(other, range(100, 101 + n)))
        tw = sps.ttest_ind(row, other, equal_var=False)
        lo, hi = tw.confidence_interval(0.95)
        assert w.method == "welch" and w.p == pytest.approx(tw.pvalue, rel=1e-9, abs=1e-15)
        assert (w.lo, w.hi) == (pytest.approx(lo, rel=1e-9), pytest.approx(hi, rel=1e-9))
        assert w.significant == (tw.pvalue < 0.05)


def test_exact_differences_have_p_zero_or_one():
    assert compare({0: 2.0, 1: 3.0}, {0: 1.0, 1: 2.0}).p == 0.0   # every difference +1: certain
    assert compare({0: 2.0, 1: 3.0}, {0: 2.0, 1: 3.0}).p == 1.0   # every difference 0: no evidence
    assert compare({0: 5.0}, {0: 4.0}).p is None                   # one seed: no interval, no p


@pytest.fixture
def no_gc_in_multipletests(monkeypatch):
    """statsmodels' Holm runs gc.collect() on every call (about 0.3 s each here); it changes no result."""
    monkeypatch.setattr(gc, "collect", lambda *args: 0)


def test_holm_matches_statsmodels(no_gc_in_multipletests):
    rng = np.random.default_rng(3)
    cases = [[0.01, 0.04, 0.03, 0.005], [0.2, 0.2, 0.01], [0.0125, 0.0125, 0.0125, 0.0125], [0.5], []]
    cases += [list(rng.uniform(0.0, 0.1, 12)) for _ in range(10)]
    for p in cases:
        ours = holm(p)
        if not p:
            assert ours == []
            continue
        reject, corrected, _, _ = multipletests(p, alpha=0.05, method="holm")
        assert ours == pytest.approx(list(corrected), abs=1e-12)
        assert [q <= 0.05 for q in ours] == list(reject)


def test_pairs_on_the_shared_seeds_and_names_the_dropped():
    # seed noise moves both rows alike; the row is 2 above on every seed. Seed 1's reference failed (absent)
    # and seed 3's row is not finite: the shared seeds 0, 2, 4 are paired, 1 and 3 dropped and named.
    noise = {0: 0.0, 1: 5.0, 2: -4.0, 3: 3.0, 4: 8.0}
    row = {s: 22.0 + v + 0.1 * s * s for s, v in noise.items()}  # +2.0, +2.4, +3.6 on the shared seeds
    row[3] = math.nan
    ref = {s: 20.0 + v for s, v in noise.items() if s != 1}
    d = compare(row, ref)
    assert d.method == "paired" and d.n_a == d.n_b == 3 and d.dropped == (1, 3)
    t = sps.ttest_rel([row[s] for s in (0, 2, 4)], [ref[s] for s in (0, 2, 4)])
    lo, hi = t.confidence_interval(0.95)
    assert (d.lo, d.hi) == (pytest.approx(lo), pytest.approx(hi)) and d.significant
    assert d.text(2).endswith("* (n=3, paired; dropped seeds 1, 3)")
    # the same values unpaired (the old rule after one failure) could not tell +2 from zero
    w = sps.ttest_ind([v for v in row.values() if math.isfinite(v)], list(ref.values()), equal_var=False)
    assert w.pvalue > 0.05


def test_welch_only_without_shared_seeds():
    d = compare({0: 1.0, 1: 2.0, 2: 3.0}, {5: 2.0, 6: 2.5})
    assert d.method == "welch" and d.dropped == () and d.text(2).endswith("(n=3 vs 2)")
    runs = compare({"run/a": 1.0, "run/b": 2.0}, {"run/c": 2.0, "run/d": 2.5})  # runs without a seed
    assert runs.method == "welch" and runs.dropped == () and runs.unseeded_dropped == 0
    # one shared seed pairs (on one seed: no interval), it does not fall back to Welch
    one = compare({0: 1.0, 1: 2.0, 2: 3.0}, {0: 2.0, 7: 2.5})
    assert one.method == "paired" and not one.has_interval and one.dropped == (1, 2, 7)
    assert one.text(2) == "-1.00 [n/a: one seed] (n=1, paired; dropped seeds 1, 2, 7)"
    # a non-finite value in a Welch comparison is named too
    assert compare({0: 1.0, 1: math.inf, 2: 3.0}, {5: 2.0, 6: 2.5}).dropped == (1,)


def test_paired_drops_runs_without_a_seed_and_says_so():
    d = compare({0: 1.0, 1: 2.5, "run/x": 9.0}, {0: 0.0, 1: 1.0})
    assert d.method == "paired" and d.unseeded_dropped == 1 and d.dropped == ()
    assert d.text(2).endswith("(n=2, paired; dropped 1 run without a seed)")


def test_many_dropped_seeds_are_cut_short():
    d = compare({s: float(s) for s in range(20)}, {0: 0.0, 1: 0.5, 2: 1.0})
    assert len(d.dropped) == 17
    assert d.text(2).endswith("dropped seeds 3, 4, 5, 6, 7, 8, 9, 10 +9 more)")
