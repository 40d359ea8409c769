"""Differences between two table rows with a 95 % confidence interval, and Pearson r with its
Fisher-z interval.

Why here: the seed intervals and the paper-claims verdicts must use the same rule. Two rows with
the same seeds are paired by seed (same seed = same initialisation and priors, so the paired
difference removes that shared noise); otherwise Welch's unequal-variance t interval is used.
With fewer than two values on a side there is no interval (shown as n/a, never as zero width).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats as sps

LEVEL = 0.95


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

    @property
    def has_interval(self) -> bool:
        return self.lo is not None and self.hi is not None

    @property
    def significant(self) -> bool:
        """The interval excludes zero."""
        return self.has_interval and (self.lo > 0.0 or self.hi < 0.0)  # type: ignore[operator]

    def text(self, decimals: int) -> str:
        if self.delta is None:
            return f"n/a ({self.reason})" if self.reason else "–"
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
    out.delta = float(xa.mean() - xb.mean())
    if set(a) == set(b) and all(isinstance(s, int) for s in a):
        out.method = "paired"
        d = np.array([a[s] - b[s] for s in sorted(a)], dtype=np.float64)
        if d.size < 2:
            out.reason = "one seed"
            return out
        half = t_quantile(d.size - 1) * float(d.std(ddof=1)) / math.sqrt(d.size)
    else:
        out.method = "welch"
        if xa.size < 2 or xb.size < 2:
            out.reason = "one seed"
            return out
        va, vb = float(xa.var(ddof=1)) / xa.size, float(xb.var(ddof=1)) / xb.size
        se2 = va + vb
        if se2 <= 0.0:  # no spread on either side: the difference is exact
            half = 0.0
        else:
            # Welch-Satterthwaite degrees of freedom; a side without spread contributes no term
            den = (va * va / (xa.size - 1) if va > 0 else 0.0) + (vb * vb / (xb.size - 1) if vb > 0 else 0.0)
            dof = se2 * se2 / den
            half = t_quantile(dof) * math.sqrt(se2)
    out.lo, out.hi = out.delta - half, out.delta + half
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
