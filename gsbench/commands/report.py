"""`gsbench report RUNS_DIR --out REPORT_DIR`: Markdown and LaTeX tables, PNG plots and a static
index.html, built from the collected results (plus the runs' train_log.jsonl for curves and loss
shares, and their results.json for the training budget)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from gsbench.errors import InputError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("runs_dir", type=Path,
                        help="runs folder (collected now), or a collected.parquet / collected.csv file")
    parser.add_argument("--out", type=Path, required=True,
                        help="report folder (index.html, tables/, plots/): new, empty or an earlier report")
    parser.add_argument("--force", action="store_true",
                        help="write into a folder that holds files the report did not write; they are kept")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--print", dest="print_tables", nargs="+", metavar="TABLE_ID", default=[],
                        help="print these tables (Markdown) after building, e.g. paper_claims loss_subsets_diff")


def run(args: argparse.Namespace) -> int:
    from gsbench.reports.build import build_report  # lazy: start-up (cli loads all commands)

    summary = build_report(args.runs_dir, args.out, progress=not args.no_progress, force=args.force)
    unknown = [t for t in args.print_tables if t not in summary.tables]
    if unknown:
        raise InputError(f"{args.runs_dir}: no table {', '.join(unknown)} in this report "
                         f"(tables: {', '.join(summary.tables) or 'none'})")
    for t in args.print_tables:
        print((summary.out_dir / "tables" / f"{t}.md").read_text(encoding="utf-8"))
    for n in summary.notes:
        print(f"gsbench report: note: {n}", file=sys.stderr)
    print(f"{len(summary.tables)} tables ({', '.join(summary.tables) or 'none'}), {len(summary.plots)} plots")
    if summary.unreadable:
        print(f"gsbench report: could not read {summary.unreadable} results.json file(s) (reported as failed runs)",
              file=sys.stderr)
    print(f"Report: {summary.index}")
    return 0
