"""gsbench.reports: tables (Markdown, LaTeX, HTML), plots and a static HTML page built only from
the collected results (gsbench.collect), the runs' train_log.jsonl (curves, loss shares) and, for the
training budget when the collected table lacks it, the runs' results.json.

Entry point: `build_report(runs_dir_or_collected_file, out_dir) -> ReportSummary`.
"""
from __future__ import annotations

from typing import Any

__all__ = ["build_report", "ReportSummary"]


def __getattr__(name: str) -> Any:
    if name in ("build_report", "ReportSummary"):
        from gsbench.reports import build  # lazy: importing the package must not import matplotlib
        return getattr(build, name)
    raise AttributeError(name)
