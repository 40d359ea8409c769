"""Judging a re-run on another CPU by the seed spread of its setting (`gsbench verify`).

Why: CPU training is exact only on the CPU family that published a cell. Elsewhere one ulp in the
first steps grows, over hundreds of steps, into a difference the size of a seed's. Comparing the
re-run with one published number at a fixed tolerance then fails on every other machine and tells
a reader nothing. The question a reader brings is whether the published number holds: is the re-run
a plausible draw from the same setting? So each re-run metric is judged against a prediction
interval built from the published seeds of its setting (the same grid, method, axes and scene; only
the seed differs): mean +- t(1 - ALPHA/2, n-1) * sd * sqrt(1 + 1/n), the interval that holds a new
draw from the same normal distribution with probability 1 - ALPHA.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any, Iterable, Optional

from scipy import stats

from gsbench.collect import number_problem

ALPHA = 0.01            # each metric's prediction interval holds a new seed with probability 0.99
# A setting whose seeds all gave the same value (a metric of the scene or the priors, not of the
# training) has no spread: its interval is the value within this relative width, so that an ulp of
# another CPU's libm is within it and a real change is not.
POINT_RTOL = 1e-6
# Metrics that one ulp can flip, named as such in the output (docs/publishing.md): localisation is
# a thresholded hit or miss per query, and encode-mode queries compare a text feature with a
# relevancy threshold, so a run one ulp away can gain or lose a whole query.
FLIP_PRONE_PARTS = ("loc_acc_", "_encode")

WITHIN, OUTSIDE, NO_SPREAD, BOTH_NULL, NULL_ONE_SIDE = (
    "within the seed spread", "outside", "no seed spread", "null on both sides", "null on one side")


def flip_prone(metric: str) -> bool:
    """A metric that a one-ulp change of the training can flip (FLIP_PRONE_PARTS)."""
    return any(p in metric for p in FLIP_PRONE_PARTS)


def setting_key(record: dict) -> str:
    """The setting a published cell belongs to: its grid, method, axes and scene (not its seed)."""
    cell = record.get("cell") or {}
    return json.dumps([record.get("grid"), cell.get("method"), cell.get("axes"), cell.get("scene")],
                      sort_keys=True, default=str)


def prediction_interval(values: list[float], alpha: float = ALPHA) -> Optional[tuple[float, float]]:
    """The (1 - alpha) prediction interval of one new draw, from `values` (None for fewer than 2)."""
    n = len(values)
    if n < 2:
        return None
    mean = math.fsum(values) / n
    var = math.fsum((v - mean) ** 2 for v in values) / (n - 1)
    sd = math.sqrt(max(var, 0.0))
    if sd == 0.0:
        half = POINT_RTOL * abs(mean)
    else:
        half = float(stats.t.ppf(1.0 - alpha / 2.0, n - 1)) * sd * math.sqrt(1.0 + 1.0 / n)
    return mean - half, mean + half


@dataclass
class SpreadRow:
    """One metric of a re-run judged against its setting's published seeds."""
    metric: str
    published: Any
    now: Any
    interval: Optional[tuple[float, float]]
    n: int
    verdict: str

    @property
    def ok(self) -> bool:
        """Fails only outside the spread, or where one side computed a value the other did not."""
        return self.verdict not in (OUTSIDE, NULL_ONE_SIDE)

    @property
    def flip_prone(self) -> bool:
        return flip_prone(self.metric)


def as_number(v: Any) -> Optional[float]:
    """A stored metric as a finite float; None for null and for anything collect's `number_problem`
    refuses (a string, a bool, a non-finite or an out-of-range value such as a 401-digit integer)."""
    return None if v is None or number_problem(v) else float(v)


def _seed_values(records: Iterable[dict], metric: str) -> list[float]:
    out = []
    for rec in records:
        f = as_number(((rec.get("results") or {}).get("metrics") or {}).get(metric))
        if f is not None:
            out.append(f)
    return out


def judge(metric: str, published: Any, now: Any, same_setting: list[dict], alpha: float = ALPHA) -> SpreadRow:
    """The re-run's value of `metric` against the published seeds of its setting (`same_setting`:
    their records, the cell's own included)."""
    values = _seed_values(same_setting, metric)
    pi = prediction_interval(values, alpha)
    if published is None and now is None:
        return SpreadRow(metric, published, now, pi, len(values), BOTH_NULL)
    if now is None or published is None:
        return SpreadRow(metric, published, now, pi, len(values), NULL_ONE_SIDE)
    value = as_number(now)
    if pi is None and value is not None:
        return SpreadRow(metric, published, now, pi, len(values), NO_SPREAD)
    inside = value is not None and pi is not None and pi[0] <= value <= pi[1]
    return SpreadRow(metric, published, now, pi, len(values), WITHIN if inside else OUTSIDE)


def judge_all(published: dict, now: dict, same_setting: list[dict], skip: frozenset,
              alpha: float = ALPHA) -> list[SpreadRow]:
    """Every metric of either side but those in `skip` (timings), judged by `judge`."""
    return [judge(m, published.get(m), now.get(m), same_setting, alpha)
            for m in sorted(set(published) | set(now)) if m not in skip]
