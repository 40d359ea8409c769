"""Differences between two table rows with a 95 % confidence interval, and Pearson r with its
Fisher-z interval.

Why here: the seed intervals and the paper-claims verdicts must use the same rule. Two rows with
the same seeds are paired by seed (same seed = same initialisation and priors, so the paired
difference removes that shared noise); otherwise Welch's unequal-variance t interval is used.
With fewer than two values on a side there is no interval (shown as n/a, never as zero width).

The minimum detectable effect (MDE) says what a study could have found: the smallest true difference
a two-sided 5 % test on this design detects with 80 % power, from the observed spread. Paired by seed:
MDE = (t_{0.975,n-1} + t_{0.80,n-1}) * sd_diff / sqrt(n), the textbook normal-shift approximation with
t quantiles (the exact non-central t answer is a little larger at very small n). Welch: the same sum of
quantiles at the Welch-Satterthwaite degrees of freedom times sqrt(sd_a^2/n_a + sd_b^2/n_b). With fewer
than two values on a side there is no spread to size it from, so no MDE (n/a), never zero.
For a Pearson r: the smallest |r| detected at n runs, tanh((z_{0.975} + z_{0.80}) / sqrt(n - 3)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats as sps

LEVEL = 0.95
POWER = 0.80


@dataclass
class Diff:
    """Mean difference (row minus reference) and its two-sided 95 % interval."""
    delta: float | None = None
    lo: float | None = None
    hi: float | None = None
    n_a: int = 0
    n_b: int = 0
    method: str = ""          # "paired" | "welch" | ""
    reason: str | None = None  # why there is no interval (or no difference)
    mde: float | None = None   # minimum detectable effect at this n (module docstring), None = no spread

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
        tag = f"n={self.n_a}, paired" if self.method == "paired" else f"n={self.n_a} vs {self.n_b}"
        return s + f" ({tag})"


def t_quantile(df: float) -> float:
    """Two-sided 95 % quantile of Student's t with df degrees of freedom."""
    return float(sps.t.ppf(0.5 + LEVEL / 2.0, df))


def power_quantile(df: float) -> float:
    """One-sided quantile of Student's t at the power (80 %) with df degrees of freedom."""
    return float(sps.t.ppf(POWER, df))


def mde_t(se: float, df: float) -> float:
    """Minimum detectable effect of a t test with standard error se and df degrees of freedom."""
    return (t_quantile(df) + power_quantile(df)) * se


def mde_r(n: int) -> float | None:
    """Smallest |Pearson r| a two-sided 5 % test detects with 80 % power at n points (needs n > 3)."""
    if n <= 3:
        return None
    z = float(sps.norm.ppf(0.5 + LEVEL / 2.0)) + float(sps.norm.ppf(POWER))
    return math.tanh(z / math.sqrt(n - 3))


def _mean_sd(x: np.ndarray) -> tuple[float, float]:
    """Mean and sample std (ddof=1) computed on x / max|x|, so values near the float64 limit do not
    overflow in the sum or the squares."""
    s = float(np.max(np.abs(x)))
    if s == 0.0:
        return 0.0, 0.0
    y = x / s
    return s * float(y.mean()), (s * float(y.std(ddof=1)) if x.size > 1 else 0.0)


def compare(a: dict, b: dict) -> Diff:
    """Row values by seed `a` against reference values by seed `b` (non-finite values ignored).
    Keys are seeds (int); a run without a seed is keyed by its run id and never paired."""
    a = {s: float(v) for s, v in a.items() if v is not None and math.isfinite(v)}
    b = {s: float(v) for s, v in b.items() if v is not None and math.isfinite(v)}
    out = Diff(n_a=len(a), n_b=len(b))
    if not a or not b:
        out.reason = "no value" if not a else "no reference value"
        return out
    xa = np.array(list(a.values()), dtype=np.float64)
    xb = np.array(list(b.values()), dtype=np.float64)
    (ma, sa), (mb, sb) = _mean_sd(xa), _mean_sd(xb)
    if set(a) == set(b) and all(isinstance(k, int) for k in a):
        out.method = "paired"
        d = np.array([a[k] / 2.0 - b[k] / 2.0 for k in sorted(a)], dtype=np.float64)  # halves: no overflow
        md, sd = _mean_sd(d)
        delta = 2.0 * md
        if d.size < 2:
            half = mde = None
        else:
            se = 2.0 * sd / math.sqrt(d.size)
            half, mde = t_quantile(d.size - 1) * se, mde_t(se, d.size - 1)
    else:
        out.method = "welch"
        delta = ma - mb
        if xa.size < 2 or xb.size < 2:
            half = mde = None
        else:
            ea, eb = sa / math.sqrt(xa.size), sb / math.sqrt(xb.size)  # standard errors
            se = math.hypot(ea, eb)
            if se == 0.0:  # no spread on either side: the difference is exact
                half = mde = 0.0
            else:
                # Welch-Satterthwaite degrees of freedom, on shares of se (no squares of large values)
                pa, pb = ea / se, eb / se
                dof = 1.0 / (pa ** 4 / (xa.size - 1) + pb ** 4 / (xb.size - 1))
                half, mde = t_quantile(dof) * se, mde_t(se, dof)
    if not math.isfinite(delta) or (half is not None and not math.isfinite(half)):
        out.reason = "difference overflows float64"
        return out
    out.delta = delta
    out.mde = mde if mde is not None and math.isfinite(mde) else None
    if half is None:
        out.reason = "one seed"
        return out
    out.lo, out.hi = delta - half, delta + half
    return out


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
