"""The tests behind the paper-claims verdicts that the plain paired interval (reports/stats.py) does not
give: the equivalence test of a robustness claim, the within-seed analysis of a lambda claim, and the
type I error of two looks at the data.

Why separate tests: each verdict must say what its data support.
- Robustness ("no real change") is an equivalence question, so it is read by TOST (two one-sided t
  tests against -margin and +margin, each at TOST_ALPHA = 5 %; equivalent to the 90 % interval lying
  inside +-margin). Its seed rule is an equivalence test's: the paired seeds at which TOST has 80 %
  power when the true difference is zero (`tost_power`, exact: the estimate's normal distribution
  integrated over the chi-square distribution of its standard error).
- The lambda grid's seeds explain nearly all of mIoU's variance, so a correlation pooled over seeds
  mostly measures the seeds. `within_seed` fits the seed fixed-effects model (OLS of the metric on
  lambda with one intercept per seed): its slope with a t interval, and the within-seed (partial)
  Pearson r with a Fisher-z interval on n - k - 2 (k seeds). The slope's t test and the r test are the
  same test. Its seed rule counts seeds: a seed adds its lambda settings as runs and one intercept.
- Two looks at 5 % (a grid's seeds extended after its results were seen) reject a true null more than
  5 % of the time; `two_look_error` measures by how much, by simulation with a fixed RNG seed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import integrate
from scipy import stats as sps

from gsbench.reports.stats import LEVEL, POWER, SEEDS_CAP, mde_r, p_two_sided, pearson_interval, t_quantile

TOST_ALPHA = 0.05          # each one-sided test of the equivalence test
TWO_LOOK_DRAWS = 200_000   # null experiments per two-look simulation
TWO_LOOK_RNG_SEED = 49     # the simulation's RNG seed (the page prints its result)


# ----------------------------------------------------------------------------- equivalence (TOST)
@dataclass
class Tost:
    """The equivalence test of a difference against +-margin: the two one-sided p-values, the TOST p
    (the larger: both must reject), the (1 - 2 alpha) interval it is equivalent to, and the one-sided
    p of "the difference lies below -margin" (a harmful effect beyond the margin)."""
    p: float
    p_lower: float
    p_upper: float
    lo: float
    hi: float
    p_harm: float


def tost(delta: float, se: float, df: float, margin: float, alpha: float = TOST_ALPHA) -> Tost:
    """TOST of a mean difference `delta` with standard error `se` on df degrees of freedom."""
    if not (margin > 0.0 and se >= 0.0 and df > 0.0 and math.isfinite(delta)):
        raise ValueError(f"TOST needs margin > 0, se >= 0, df > 0, finite delta; got {margin}, {se}, {df}, {delta}")
    if se == 0.0:   # exact difference: each side rejects or not with certainty
        p_lo, p_hi, p_harm = float(delta <= -margin), float(delta >= margin), float(delta >= -margin)
        return Tost(max(p_lo, p_hi), p_lo, p_hi, delta, delta, p_harm)
    p_lo = float(sps.t.sf((delta + margin) / se, df))     # H0: delta <= -margin
    p_hi = float(sps.t.cdf((delta - margin) / se, df))    # H0: delta >= +margin
    half = float(sps.t.ppf(1.0 - alpha, df)) * se
    return Tost(max(p_lo, p_hi), p_lo, p_hi, delta - half, delta + half, 1.0 - p_lo)


def tost_power(sd: float, n: int, margin: float, alpha: float = TOST_ALPHA, true: float = 0.0) -> float:
    """Power of the paired TOST (n seeds, sd of the paired differences) at a true difference `true`.
    It rejects when -margin + c S < D < margin - c S (c the one-sided t quantile, S the estimated standard
    error): D ~ N(true, sd^2/n), S = sd/sqrt(n) sqrt(V/df) with V ~ chi-square(df), so the power is the
    normal probability of that band integrated over V (zero once the band is empty)."""
    if n < 2 or not (sd >= 0.0 and margin > 0.0):
        raise ValueError(f"TOST power needs n >= 2, sd >= 0, margin > 0; got n={n}, sd={sd}, margin={margin}")
    if sd == 0.0:
        return float(abs(true) < margin)
    df, se = n - 1, sd / math.sqrt(n)
    c = float(sps.t.ppf(1.0 - alpha, df))
    v_max = df * (margin / (c * se)) ** 2   # beyond it, m - c S < 0: the band is empty

    def band(v: float) -> float:
        s = se * math.sqrt(v / df)
        p = sps.norm.cdf((margin - c * s - true) / se) - sps.norm.cdf((-margin + c * s - true) / se)
        return max(0.0, float(p)) * float(sps.chi2.pdf(v, df))

    value, _err = integrate.quad(band, 0.0, v_max, limit=200, epsabs=1e-10, epsrel=1e-10)
    return min(1.0, max(0.0, float(value)))


def seeds_for_tost(sd: float, margin: float, cap: int = SEEDS_CAP) -> int | None:
    """Smallest number of paired seeds n >= 2 at which TOST (TOST_ALPHA a side) has POWER at a true
    difference of zero, with the observed sd of the differences held fixed; None beyond `cap`."""
    if not (math.isfinite(sd) and sd >= 0.0):
        raise ValueError(f"need a finite sd of the differences, got {sd}")
    for n in range(2, cap + 1):
        if tost_power(sd, n, margin) >= POWER:
            return n
    return None


# ----------------------------------------------------------------------------- within-seed analysis
@dataclass
class WithinSeed:
    """The seed fixed-effects fit of metric on lambda."""
    n: int                 # runs
    seeds: int             # seeds (intercepts)
    slope: float
    slope_lo: float
    slope_hi: float
    df: int                # residual degrees of freedom, n - seeds - 1
    t: float
    p: float               # two-sided p of the slope (= of the within-seed r)
    r: float               # within-seed (partial) Pearson r
    r_lo: float | None     # Fisher-z 95 % interval on n - seeds - 2; None when that is not positive
    r_hi: float | None


def within_seed(seeds: list, x: list[float], y: list[float]) -> tuple[WithinSeed | None, str | None]:
    """Seed fixed-effects OLS of y on x (module docstring); (None, why) when it is not defined."""
    groups: dict = {}
    for s, xi, yi in zip(seeds, x, y):
        if math.isfinite(xi) and math.isfinite(yi):
            groups.setdefault(s, []).append((xi, yi))
    xs, ys = [], []
    for pts in groups.values():
        a = np.array(pts, dtype=np.float64)
        xs.append(a[:, 0] - a[:, 0].mean())
        ys.append(a[:, 1] - a[:, 1].mean())
    n, k = sum(len(a) for a in xs), len(groups)
    df = n - k - 1
    if df < 1:
        return None, f"{n} runs on {k} seeds (need more runs than seeds + 1)"
    xc, yc = np.concatenate(xs), np.concatenate(ys)
    sxx, syy, sxy = float(xc @ xc), float(yc @ yc), float(xc @ yc)
    if sxx <= 0.0:
        return None, "lambda constant within every seed"
    if syy <= 0.0:
        return None, "metric constant within every seed"
    slope = sxy / sxx
    rss = max(0.0, float(np.sum((yc - slope * xc) ** 2)))
    se = math.sqrt(rss / df / sxx)
    r = max(-1.0, min(1.0, sxy / math.sqrt(sxx * syy)))
    t = slope / se if se > 0.0 else math.copysign(math.inf, slope)
    half = t_quantile(df) * se
    # Fisher z on n - k - 2: Pearson's interval at n - k + 1 points (the k seed means cost k - 1 more)
    r_lo, r_hi = pearson_interval(r, n - k + 1) or (None, None)
    return WithinSeed(n, k, slope, slope - half, slope + half, df, t, p_two_sided(t, df), r, r_lo, r_hi), None


def mde_within_r(n: int, seeds: int) -> float | None:
    """Smallest |within-seed r| a two-sided 5 % test detects with 80 % power at n runs on `seeds` seeds
    (Fisher z on n - seeds - 2: Pearson's MDE at n - seeds + 1 points)."""
    return mde_r(n - seeds + 1)


def p_r_against(r: float, value: float, n: int, seeds: int) -> float | None:
    """Two-sided Fisher-z p of "the within-seed r equals `value`" (the paper's r)."""
    dof = n - seeds - 2
    if dof < 1:
        return None
    clip = 1.0 - 1e-12
    z = (math.atanh(max(-clip, min(clip, r))) - math.atanh(max(-clip, min(clip, value)))) * math.sqrt(dof)
    return min(1.0, 2.0 * float(sps.norm.sf(abs(z))))


def seeds_for_within_r(target: float, runs_per_seed: int, cap: int = SEEDS_CAP) -> int | None:
    """Smallest number of seeds s at which s seeds of `runs_per_seed` lambda settings each detect a
    within-seed |r| of `target` (mde_within_r at most target); None beyond `cap`."""
    if not 0.0 < target < 1.0 or runs_per_seed < 2:
        raise ValueError(f"need 0 < target < 1 and at least 2 runs a seed; got {target}, {runs_per_seed}")
    for s in range(1, cap + 1):
        m = mde_within_r(s * runs_per_seed, s)
        if m is not None and m <= target:
            return s
    return None


# ----------------------------------------------------------------------------- two looks
def two_look_error(n1: int, n2: int, alpha: float = 1.0 - LEVEL, draws: int = TWO_LOOK_DRAWS,
                   rng_seed: int = TWO_LOOK_RNG_SEED) -> float:
    """Type I error of a paired two-sided t test at level `alpha` looked at twice, at n1 seeds and again
    at n2 > n1 (the first n1 plus n2 - n1 more), rejecting when either look rejects: the share of
    `draws` null experiments (standard normal differences, numpy PCG64 with `rng_seed`) that reject."""
    if not 2 <= n1 < n2:
        raise ValueError(f"two looks need 2 <= n1 < n2, got n1={n1}, n2={n2}")
    rng = np.random.Generator(np.random.PCG64(rng_seed))
    x = rng.standard_normal((draws, n2))

    def rejects(a: np.ndarray) -> np.ndarray:
        n = a.shape[1]
        t = a.mean(axis=1) / (a.std(axis=1, ddof=1) / math.sqrt(n))
        return np.abs(t) > float(sps.t.ppf(1.0 - alpha / 2.0, n - 1))

    return float(np.mean(rejects(x[:, :n1]) | rejects(x)))
