"""The names of runs in figures' legends: method, scene, the grid axis values a run has, seed; runs whose
names collide get their run folder's name (or config key). Plots and the loss-share figure name runs
alike through it."""
from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

from gsbench.reports.data import Results, is_null
from gsbench.reports.display import method_label


def run_label(res: Results, rid: str) -> str:
    """Short name of a run for legends: method, scene, the axis values it has, seed."""
    r = res.runs.loc[rid]
    parts = [method_label(r["method"]), str(r["scene"])]
    for c in res.axis_columns:
        v = r.get(c)
        if not is_null(v) and c != "axis.method":
            parts.append(f"{c.rsplit('.', 1)[-1]}={_fmt(v)}")
    if not is_null(r.get("seed")):
        parts.append(f"s{int(r['seed'])}")
    return " ".join(parts)


def run_labels(res: Results, run_ids: list[str]) -> dict[str, str]:
    """run_label of each run; runs whose labels collide (they differ only outside the grid axes, e.g. by
    preset or schedule) get their run folder's name, or their config key, appended."""
    labels = {rid: run_label(res, rid) for rid in run_ids}
    shared = {v for v, n in Counter(labels.values()).items() if n > 1}
    for rid in [r for r in run_ids if labels[r] in shared]:
        folder = Path(str(res.runs.at[rid, "run_dir"])).name
        tag = folder if folder != rid else str(res.runs.at[rid, "config_key"])[:8]
        labels[rid] = f"{labels[rid]} [{tag}]"
    return labels


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


__all__ = ["run_label", "run_labels"]
