"""Differences between two table rows with a 95 % confidence interval and its p-value, Holm's
correction for a family of them, and Pearson r with its Fisher-z interval.

Why here: the seed intervals, the paper-claims verdicts and the positive controls must use the same
rule. Two rows are paired on their shared seeds (a seed present with a finite value on both sides:
same seed = same initialisation and priors, so the paired difference removes that shared noise); a
seed on one side only, or with a non-finite value, is dropped and named (`Diff.dropped`). Welch's
unequal-variance t interval is used only when the rows share no seed (different seeds, or runs without
one). With fewer than two values on a side there is no interval (shown as n/a, never as zero width).
The p-value is two-sided, from the same t statistic and degrees of freedom as the interval, so
"p < 0.05" and "the interval excludes zero" agree.

The minimum detectable effect (MDE) says what a study could have found: the smallest true difference
a two-sided 5 % t test on this design detects with 80 % power, from the observed spread. It is exact:
the noncentrality lambda at which the noncentral t (df degrees of freedom) falls beyond the two-sided
critical value with probability 0.80, times the standard error. Paired: df = n - 1, se = sd_diff /
sqrt(n); Welch: the Welch-Satterthwaite df, se = sqrt(sd_a^2/n_a + sd_b^2/n_b). With fewer than two
values on a side there is no spread to size it from, so no MDE (n/a), never zero.
For a Pearson r: the smallest |r| detected at n runs, tanh((z_{0.975} + z_{0.80}) / sqrt(n - 3)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import stats as sps
from scipy.optimize import brentq

LEVEL = 0.95
ALPHA = 1.0 - LEVEL
POWER = 0.80
SEEDS_CAP = 1000  # the most seeds `seeds_for_mde` searches before it answers "more than this"
_SHOWN_SEEDS = 8  # dropped seeds named in a cell before "+k more"


@dataclass
class Diff:
    """Mean difference (row minus reference), its two-sided 95 % interval and p-value."""
    delta: float | None = None
    lo: float | None = None
    hi: float | None = None
    n_a: int = 0
    n_b: int = 0
    method: str = ""          # "paired" | "welch" | ""
    reason: str | None = None  # why there is no interval (or no difference)
    mde: float | None = None   # minimum detectable effect at this n (module docstring), None = no spread
    p: float | None = None     # two-sided p-value of the t statistic the interval uses, None = no interval
    dropped: tuple[int, ...] = ()  # seeds left out: on one side only, or not finite on a side
    unseeded_dropped: int = 0      # runs without a seed left out of a paired comparison
    se: float | None = None        # standard error of the difference, None = no spread
    df: float | None = None        # degrees of freedom of its t statistic, None = no spread

    @property
    def has_interval(self) -> bool:
        return self.lo is not None and self.hi is not None

    @property
    def significant(self) -> bool:
        """The interval excludes zero."""
        return self.has_interval and (self.lo > 0.0 or self.hi < 0.0)  # type: ignore[operator]

    def text(self, decimals: int) -> str:
        """'+d [lo, hi] * (n)'; with more decimals than the metric's when the interval's half-width would
        otherwise round to zero (a real but tiny difference must not read as '+0.00 [+0.00, +0.00] *')."""
        if self.delta is None:
            return f"n/a ({self.reason})" if self.reason else "–"
        if self.has_interval:
            half = (self.hi - self.lo) / 2.0  # type: ignore[operator]
            # the smallest number that must stay visible: the half-width, and for a marked interval the
            # bound nearest zero (so "[+0.0000, ...] *" cannot happen)
            tiny = min([half] + ([min(abs(self.lo), abs(self.hi))] if self.significant else []))  # type: ignore[arg-type]
            if 0.0 < tiny < 10.0 ** -decimals:
                decimals = min(max(decimals, 1 - math.floor(math.log10(tiny))), 12)
        s = f"{self.delta:+.{decimals}f}"
        if self.has_interval:
            s += f" [{self.lo:+.{decimals}f}, {self.hi:+.{decimals}f}]"
            if self.significant:
                s += " *"
        else:
            s += f" [n/a: {self.reason}]"
        return s + self.tag()

    def tag(self) -> str:
        """' (n=3, paired)' / ' (n=3 vs 4)', with the seeds left out."""
        n = f"n={self.n_a}, paired" if self.method == "paired" else f"n={self.n_a} vs {self.n_b}"
        return f" ({n}{self.dropped_text()})"

    def dropped_text(self) -> str:
        """'; dropped seeds 1, 4' (and runs without a seed), or '' when every value was used."""
        out = ""
        if self.dropped:
            shown = ", ".join(str(s) for s in self.dropped[:_SHOWN_SEEDS])
            more = len(self.dropped) - _SHOWN_SEEDS
            plural = "s" if len(self.dropped) > 1 else ""
            out += f"; dropped seed{plural} {shown}" + (f" +{more} more" if more > 0 else "")
        if self.unseeded_dropped:
            n = self.unseeded_dropped
            out += f"; dropped {n} run{'s' if n > 1 else ''} without a seed"
        return out


def t_quantile(df: float) -> float:
    """Two-sided 95 % quantile of Student's t with df degrees of freedom."""
    return float(sps.t.ppf(0.5 + LEVEL / 2.0, df))


def mean_band(values: list[float]) -> tuple[float, float | None]:
    """Mean and the half-width of its 95 % t interval (None with one value)."""
    n = len(values)
    m = math.fsum(values) / n
    if n < 2:
        return m, None
    sd = math.sqrt(math.fsum((v - m) ** 2 for v in values) / (n - 1))
    return m, t_quantile(n - 1) * sd / math.sqrt(n)


def t_power(ncp: float, df: float) -> float:
    """Power of the two-sided 5 % t test at df degrees of freedom when the t statistic is noncentral
    with noncentrality ncp. The lower tail is read as the upper tail at -ncp: scipy's nct.cdf returns
    NaN for some far lower tails, its sf does not."""
    crit = t_quantile(df)
    power = float(sps.nct.sf(crit, df, ncp)) + float(sps.nct.sf(crit, df, -ncp))
    if not math.isfinite(power):
        raise FloatingPointError(f"noncentral t power is not finite at df={df:g}, ncp={ncp:g}")
    return power


@lru_cache(maxsize=512)
def ncp_for_power(df: float) -> float:
    """The noncentrality at which the two-sided 5 % t test at df degrees of freedom reaches 80 % power
    (cached: paired designs repeat the same df)."""
    hi = t_quantile(df) + float(sps.norm.ppf(POWER)) + 1.0
    for _ in range(60):  # power rises with ncp towards 1; doubling brackets the root in a few steps
        if t_power(hi, df) >= POWER:
            break
        hi *= 2.0
    else:
        raise FloatingPointError(f"no noncentrality reaches {POWER:.0%} power at df={df:g}")
    return float(brentq(lambda x: t_power(x, df) - POWER, 0.0, hi, xtol=1e-12, rtol=1e-12))


def mde_t(se: float, df: float) -> float:
    """Minimum detectable effect of a two-sided 5 % t test with standard error se and df degrees of
    freedom at 80 % power (exact, noncentral t)."""
    return 0.0 if se == 0.0 else ncp_for_power(float(df)) * se


def p_two_sided(t: float, df: float) -> float:
    """Two-sided p-value of Student's t statistic t at df degrees of freedom (|t| = inf gives 0)."""
    return min(1.0, 2.0 * float(sps.t.sf(abs(t), df)))


def holm(pvalues: list[float]) -> list[float]:
    """Holm-Bonferroni adjusted p-values, in the input order: the i-th smallest of m is multiplied by
    m - i + 1, made non-decreasing in that order and capped at 1. A hypothesis is rejected at the family-wise
    level ALPHA when its adjusted p-value is <= ALPHA."""
    m = len(pvalues)
    order = sorted(range(m), key=lambda i: pvalues[i])
    out = [1.0] * m
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * pvalues[i]))
        out[i] = running
    return out


def family_note(k: int) -> str:
    """The family-wise reading of a table's k intervals at 95 %: how many exclude zero by chance alone."""
    return (f"This table has {k} interval{'s' if k != 1 else ''} at 95 %: when no effect exists, about "
            f"0.05 · {k} = {ALPHA * k:.1f} of them exclude zero by chance.")


def _z_power() -> float:
    """z_0.975 + z_0.80: the normal-theory noncentrality of a two-sided 5 % test at 80 % power."""
    return float(sps.norm.ppf(0.5 + LEVEL / 2.0)) + float(sps.norm.ppf(POWER))


def mde_r(n: int) -> float | None:
    """Smallest |Pearson r| a two-sided 5 % test detects with 80 % power at n points (needs n > 3)."""
    if n <= 3:
        return None
    return math.tanh(_z_power() / math.sqrt(n - 3))


def seeds_for_mde(se: float, n: int, target: float, cap: int = SEEDS_CAP) -> int | None:
    """Smallest number of paired seeds m >= 2 at which a paired design with the observed spread (sd of
    the differences = se * sqrt(n), held fixed) has an MDE of at most `target`; None when more than
    `cap` would be needed. The MDE falls as m grows (both the standard error and the noncentrality do),
    and the noncentrality is never below z_0.975 + z_0.80, so the search starts at that bound."""
    if not target > 0.0 or not math.isfinite(target):
        raise ValueError(f"target MDE must be a positive number, got {target}")
    if n < 2 or not math.isfinite(se) or se < 0.0:
        raise ValueError(f"need a finite standard error from n >= 2 seeds, got se={se}, n={n}")
    sd = se * math.sqrt(n)
    start = max(2, math.floor((_z_power() * sd / target) ** 2))
    for m in range(start, cap + 1):
        if mde_t(sd / math.sqrt(m), m - 1) <= target:
            return m
    return None


def runs_for_r(target: float) -> int:
    """Smallest number of runs n at which the smallest detectable |Pearson r| (`mde_r`) is at most
    `target` (0 < target < 1)."""
    if not 0.0 < target < 1.0:
        raise ValueError(f"target |r| must lie in (0, 1), got {target}")
    n = 3 + math.ceil((_z_power() / math.atanh(target)) ** 2)
    while n > 4 and mde_r(n - 1) <= target:  # ceil of a float: step back if one fewer already reaches it
        n -= 1
    return n


def _mean_sd(x: np.ndarray) -> tuple[float, float]:
    """Mean and sample std (ddof=1) computed on x / max|x|, so values near the float64 limit do not
    overflow in the sum or the squares."""
    s = float(np.max(np.abs(x)))
    if s == 0.0:
        return 0.0, 0.0
    y = x / s
    return s * float(y.mean()), (s * float(y.std(ddof=1)) if x.size > 1 else 0.0)


def _finite(values: dict) -> dict:
    return {k: float(v) for k, v in values.items() if v is not None and math.isfinite(v)}


def _seeds(keys) -> set[int]:
    """The seeds among the keys (a run without a seed is keyed by its run id, a string)."""
    return {k for k in keys if isinstance(k, int) and not isinstance(k, bool)}


def _interval(out: Diff, delta: float, se: float | None, df: float | None, t: float | None) -> Diff:
    """Fill out's difference, interval, p-value and MDE from delta, its standard error and df (se None:
    one value on a side, no spread)."""
    half = None if se is None else t_quantile(df) * se  # type: ignore[arg-type]
    if not math.isfinite(delta) or (half is not None and not math.isfinite(half)):
        out.reason = "difference overflows float64"
        return out
    out.delta = delta
    if se is None:
        out.reason = "one seed"
        return out
    out.se, out.df = se, df
    mde = mde_t(se, df)  # type: ignore[arg-type]
    out.mde = mde if math.isfinite(mde) else None
    out.lo, out.hi = delta - half, delta + half  # type: ignore[operator]
    # se == 0: the difference is exact; any nonzero one is certain, zero is no evidence
    out.p = p_two_sided(t, df) if t is not None else (0.0 if delta != 0.0 else 1.0)  # type: ignore[arg-type]
    return out


def compare(a: dict, b: dict) -> Diff:
    """Row values by seed `a` against reference values by seed `b` (module docstring: paired on the
    shared seeds, Welch when there are none). Keys are seeds (int); a run without a seed is keyed by its
    run id and never paired."""
    fa, fb = _finite(a), _finite(b)
    shared = sorted(_seeds(fa) & _seeds(fb))
    if shared:
        used_a = used_b = set(shared)
    else:
        used_a, used_b = set(fa), set(fb)
    out = Diff(n_a=len(fa), n_b=len(fb))
    out.dropped = tuple(sorted((_seeds(a) - used_a) | (_seeds(b) - used_b)))
    if not fa or not fb:
        out.reason = "no value" if not fa else "no reference value"
        return out
    if shared:
        out.method, out.n_a, out.n_b = "paired", len(shared), len(shared)
        out.unseeded_dropped = len(set(fa) - _seeds(fa)) + len(set(fb) - _seeds(fb))  # run ids: never paired
        d = np.array([fa[k] / 2.0 - fb[k] / 2.0 for k in shared], dtype=np.float64)  # halves: no overflow
        md, sd = _mean_sd(d)
        if d.size < 2:
            return _interval(out, 2.0 * md, None, None, None)
        half_se = sd / math.sqrt(d.size)
        t = md / half_se if half_se > 0.0 else None  # the t statistic is scale-free: halves give the same t
        return _interval(out, 2.0 * md, 2.0 * half_se, d.size - 1, t)
    out.method = "welch"
    xa, xb = np.array(list(fa.values())), np.array(list(fb.values()))
    (ma, sa), (mb, sb) = _mean_sd(xa), _mean_sd(xb)
    delta = ma - mb
    if xa.size < 2 or xb.size < 2:
        return _interval(out, delta, None, None, None)
    ea, eb = sa / math.sqrt(xa.size), sb / math.sqrt(xb.size)  # standard errors
    se = math.hypot(ea, eb)
    if se == 0.0:  # no spread on either side: the difference is exact
        return _interval(out, delta, 0.0, xa.size + xb.size - 2, None)
    # Welch-Satterthwaite degrees of freedom, on shares of se (no squares of large values)
    pa, pb = ea / se, eb / se
    dof = 1.0 / (pa ** 4 / (xa.size - 1) + pb ** 4 / (xb.size - 1))
    return _interval(out, delta, se, dof, delta / se if math.isfinite(delta) else None)


def pearson(x: list[float], y: list[float]) -> tuple[float | None, str | None]:
    """Pearson r with its undefined cases named instead of NaN."""
    xa, ya = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    ok = np.isfinite(xa) & np.isfinite(ya)
    xa, ya = xa[ok], ya[ok]
    if xa.size < 3:
        return None, f"{xa.size} runs with values (need 3)"
    if float(np.std(xa)) == 0.0:
        return None, "lambda constant"
    if float(np.std(ya)) == 0.0:
        return None, "metric constant"
    xc, yc = xa - xa.mean(), ya - ya.mean()
    denom = math.sqrt(float(np.sum(xc * xc)) * float(np.sum(yc * yc)))
    if denom <= 0.0:
        return None, "zero variance"
    return float(np.clip(np.sum(xc * yc) / denom, -1.0, 1.0)), None


def pearson_interval(r: float, n: int) -> tuple[float, float] | None:
    """95 % interval of Pearson r by Fisher's z (needs n > 3); |r| = 1 gives a degenerate interval."""
    if n <= 3:
        return None
    rc = min(max(r, -1.0 + 1e-12), 1.0 - 1e-12)  # atanh(+-1) is infinite
    z = math.atanh(rc)
    half = float(sps.norm.ppf(0.5 + LEVEL / 2.0)) / math.sqrt(n - 3)
    return math.tanh(z - half), math.tanh(z + half)
