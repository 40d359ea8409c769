"""The training budget of every method in the report: iterations and semantic steps per study and
method, so a reader sees whether the methods compared had the same number of steps.

Source, in this order: the collected columns budget.<key> (results.json `budget` flattened by
collect), the run's results.json `budget` dict, else the run's resolved config read by the method's
own budget rule (its spec, e.g. methods/twostage_spec.py). The source is shown per row.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from gsbench import rundir
from gsbench.methods.registry import METHODS
from gsbench.methods.registry import budget as method_budget
from gsbench.reports.data import Results, is_null
from gsbench.reports.display import method_label
from gsbench.reports.studies import ordered_methods
from gsbench.reports.table import Cell, Column, Row, Table
from gsbench.store import read_json

log = logging.getLogger(__name__)


def _int(v: Any) -> int | None:
    if is_null(v) or isinstance(v, bool):
        return None
    try:
        return int(v)
    except (TypeError, ValueError):
        return None


def run_budget(res: Results, rid: str) -> tuple[int | None, int | None, str, str | None]:
    """(iterations, semantic steps, source, schedule) of one run; None where unknown or not applicable.
    schedule: where the semantic steps sit ("joint", "after rgb", "none"), from the method's budget rule."""
    cols = res.runs.columns
    if "budget.iterations" in cols and not is_null(res.runs.at[rid, "budget.iterations"]):
        sem = res.runs.at[rid, "budget.semantic_iterations"] if "budget.semantic_iterations" in cols else None
        return _int(res.runs.at[rid, "budget.iterations"]), _int(sem), "results budget", None
    path = Path(str(res.runs.at[rid, "run_dir"])) / rundir.RESULTS
    try:
        data = read_json(path)
    except Exception as exc:  # a collected table read without its run folders
        log.debug("%s: no budget (%s)", path, exc)
        return None, None, "unknown (results.json not readable)", None
    if not isinstance(data, dict):
        return None, None, "unknown (results.json not an object)", None
    budget = data.get("budget")
    if isinstance(budget, dict) and "rgb_steps" in budget:       # what the methods record (train_summary info)
        sem = _int(budget.get("semantic_steps"))
        return _int(budget.get("rgb_steps")), (sem or None), "results budget", budget.get("schedule")
    if isinstance(budget, dict) and "iterations" in budget:
        return _int(budget.get("iterations")), _int(budget.get("semantic_iterations")), "results budget", None
    cfg = data.get("config") if isinstance(data.get("config"), dict) else {}
    method = str(res.runs.at[rid, "method"])
    if method not in METHODS:
        return None, None, f"unknown (method {method} is not registered here)", None
    try:   # the method's own budget rule (its spec), on the run's resolved config
        b = method_budget({**cfg, "method": method})
    except (KeyError, TypeError, ValueError) as exc:
        log.debug("%s: no budget from the config (%s)", path, exc)
        return None, None, "unknown (the run's config lacks what the budget rule reads)", None
    return _int(b["rgb_steps"]), (_int(b["semantic_steps"]) or None), "resolved config", b.get("schedule")


def budget_table(res: Results) -> list[Table]:
    """One row per (study, method, budget): iterations, semantic steps, source, number of runs."""
    rows = []
    studies = sorted(res.studies(), key=lambda s: (s is not None, str(s)))
    for st in studies:
        ids = res.run_ids(study=st)
        for meth in ordered_methods(res.distinct("method", ids)):
            seen: dict[tuple, int] = {}
            for rid in ids:
                if res.runs.at[rid, "method"] == meth:
                    key = run_budget(res, rid)
                    seen[key] = seen.get(key, 0) + 1
            for (it, sem, src, schedule), n in seen.items():
                sem_text = ("– (no semantic field)" if schedule == "none" else
                            f"0 ({schedule})" if sem is None and schedule not in (None, "joint", "after rgb") else
                            "n/a (unknown)" if sem is None else
                            f"{sem} (joint)" if schedule == "joint" else str(sem))
                rows.append(Row(["(standalone)" if st is None else str(st), method_label(meth)],
                                [Cell(text=str(it) if it is not None else "n/a (unknown)"), Cell(text=sem_text),
                                 Cell(text=src), Cell(text=str(n))]))
    if not rows:
        return []
    cols = [Column("iterations", "Iterations", "Iterations"), Column("semantic", "Semantic steps", "Semantic steps"),
            Column("source", "Source", "Source"), Column("runs", "Runs", "Runs")]
    return [Table("budgets", "Training budget per method",
                  "Training steps of each method per study: iterations (RGB / joint) and semantic steps "
                  "(twostage: its semantic stage after the RGB stage; GaussianDS and Gaussian Grouping: every "
                  "joint step trains the semantic field; vanilla: none).",
                  ["Study", "Method"], cols, rows, section="budgets")]
