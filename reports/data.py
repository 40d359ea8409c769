"""Access to the collected long table for the report: which runs exist, and one table cell
(mean +- sample std over the seeds of one configuration, or n/a with the reason).

Reports read nothing else than this table and the train_log.jsonl of the runs it lists.
"""
from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np
import pandas as pd

from gsbench.reports.display import LOGICAL, MetricSpec, metric_spec
from gsbench.reports.table import Cell

VALUE_COLUMNS = ("metric", "value", "metric_impl", "reason", "source")


def is_null(v: Any) -> bool:
    if v is None or v is pd.NA:
        return True
    try:
        return bool(isinstance(v, float) and math.isnan(v))
    except TypeError:
        return False


def same(a: Any, b: Any) -> bool:
    """Equality for axis values, where None / NaN / pd.NA all mean 'not set'."""
    if is_null(a) or is_null(b):
        return is_null(a) and is_null(b)
    if isinstance(a, (int, float, np.number)) and isinstance(b, (int, float, np.number)) \
            and not isinstance(a, bool) and not isinstance(b, bool):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-12)
    return a == b


class Results:
    """The long table indexed by run and metric."""

    def __init__(self, df: pd.DataFrame):
        self.df = df
        run_cols = [c for c in df.columns if c not in VALUE_COLUMNS]
        runs = df.drop_duplicates("run_id")[run_cols].copy()
        runs = runs.astype(object).where(runs.notna(), None)
        self.runs = runs.set_index("run_id", drop=False)
        self.values: dict[tuple[str, str], tuple[float, str | None]] = {}
        for rid, m, v, reason in zip(df["run_id"], df["metric"], df["value"], df["reason"]):
            if m is None or is_null(m):
                continue
            self.values[(str(rid), str(m))] = (float(v) if not is_null(v) else math.nan,
                                               None if is_null(reason) else str(reason))
        self.axis_columns = [c for c in df.columns if c.startswith("axis.")]
        # plain dicts: selecting runs is the report's inner loop, and DataFrame.iterrows is slow
        self._records = [(str(rid), row) for rid, row in zip(self.runs.index, self.runs.to_dict("records"))]
        self.long_reasons: dict[str, set[str]] = {}  # short reason shown in a cell -> full texts
        self.regime_cache: dict | None = None  # run id -> Regime (reports/regimes.py, read once)

    # ------------------------------------------------------------------ selection
    def run_ids(self, study: Any = "__any__", **eq: Any) -> list[str]:
        """Run ids whose columns equal the given values (study may be a tuple of allowed studies)."""
        out = []
        for rid, row in self._records:
            if study != "__any__":
                allowed = study if isinstance(study, tuple) else (study,)
                if not any(same(row["study"], s) for s in allowed):
                    continue
            if all(same(row.get(k), v) for k, v in eq.items()):
                out.append(str(rid))
        return out

    def studies(self) -> set:
        return {None if is_null(s) else s for s in self.runs["study"].tolist()}

    def distinct(self, column: str, run_ids: Iterable[str]) -> list:
        vals: list = []
        for rid in run_ids:
            v = self.runs.at[rid, column] if column in self.runs.columns else None
            v = None if is_null(v) else v
            if not any(same(v, x) for x in vals):
                vals.append(v)
        return vals

    def has_metric(self, run_ids: Iterable[str], metric: str) -> bool:
        return any((rid, metric) in self.values for rid in run_ids)

    def value(self, rid: str, metric: str) -> float:
        v = self.values.get((rid, metric))
        return v[0] if v is not None else math.nan

    def resolve(self, metric: str, protocol: Any) -> str | None:
        """Concrete metric for a logical one ('miou' -> miou_3dovs on a 3D-OVS scene)."""
        if metric in LOGICAL:
            return LOGICAL[metric].get(None if is_null(protocol) else protocol)
        return metric

    # ------------------------------------------------------------------ cells
    def cell(self, run_ids: list[str], metric: str | None, spec: MetricSpec | None = None,
             missing_reason: str | None = None) -> Cell:
        """Mean +- sample std (ddof=1) over the runs that are done and have a finite value."""
        spec = spec or metric_spec(metric or "")
        if not run_ids:
            return Cell(decimals=spec.decimals)
        if metric is None:
            return Cell(
                decimals=spec.decimals, total=len(run_ids), reason=missing_reason or "not defined for this protocol"
            )
        vals: list[float] = []
        reasons: list[str] = []
        for rid in run_ids:
            status = self.runs.at[rid, "status"]
            got = self.values.get((rid, metric))
            if status != "done":
                reasons.append(f"run {status}")
                continue
            if got is None:
                reasons.append("not evaluated")
                continue
            v, why = got
            if math.isfinite(v):
                vals.append(v * spec.scale)
            else:
                reasons.append(why or "no reason recorded")
        c = Cell(decimals=spec.decimals, total=len(run_ids), n=len(vals))
        if vals:
            arr = np.asarray(vals, dtype=np.float64)
            c.mean = float(arr.mean())
            c.std = float(arr.std(ddof=1)) if arr.size > 1 else None
        else:
            uniq: list[str] = []
            for r in reasons:
                if short_reason(r) not in uniq:
                    uniq.append(short_reason(r))
                if short_reason(r) != r:
                    self.long_reasons.setdefault(short_reason(r), set()).add(r)
            c.reason = "; ".join(uniq)
        return c

    def seed_values(self, run_ids: list[str], metric: str | None, scale: float = 1.0) -> dict:
        """Finite values of the finished runs, keyed by seed (run id when the seed is unknown);
        when two runs share a seed (rows merged because they are one resolved config), the first is kept."""
        out: dict = {}
        if metric is None:
            return out
        for rid in run_ids:
            if self.runs.at[rid, "status"] != "done":
                continue
            got = self.values.get((rid, metric))
            if got is None or not math.isfinite(got[0]):
                continue
            seed = self.runs.at[rid, "seed"]
            key = int(seed) if not is_null(seed) else rid
            out.setdefault(key, got[0] * scale)
        return out

    def mixed_configs(self, run_ids: list[str]) -> bool:
        """True when the runs of one cell differ by more than their seed (config hash or providers)."""
        if len(run_ids) < 2:
            return False
        cols = ["config_key"] + [c for c in self.runs.columns if c.startswith("provider.")]
        for c in cols:
            if c in self.runs.columns and len(self.distinct(c, run_ids)) > 1:
                return True
        return False


def short_reason(reason: str) -> str:
    """The head of a reason for a table cell ("no LPIPS weights: backbone ... not found" ->
    "no LPIPS weights"); the full text is listed in the report's notes."""
    head = reason.split(": ", 1)[0].strip()
    return head if len(head) >= 3 else reason


def mean_of_cells(cells: list[Cell], names: list[str], decimals: int) -> Cell:
    """Plain mean of per-scene means (the paper's 'Overall'); n/a when a scene has no value,
    because a mean over different scene sets is not comparable between rows."""
    if not cells:
        return Cell(decimals=decimals)
    missing = [names[i] for i, c in enumerate(cells) if c.mean is None or not math.isfinite(c.mean)]
    if missing:
        return Cell(decimals=decimals, total=1, reason="no value for " + ", ".join(missing))
    return Cell(mean=float(np.mean([c.mean for c in cells])), n=1, total=1, decimals=decimals)
