"""`gsbench collect RUNS_DIR`: gather every results.json under RUNS_DIR into one long table
(runs_dir/collected.parquet, or collected.csv when pyarrow is not installed)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "runs_dir", type=Path, help="folder searched recursively for results.json (hidden folders skipped)"
    )
    parser.add_argument("--out", type=Path, default=None,
                        help="folder to write collected.parquet / collected.csv into (default: RUNS_DIR)")


def run(args: argparse.Namespace) -> int:
    from gsbench.collect import collect, write_collected  # lazy: start-up (cli loads all commands)

    df = collect(args.runs_dir)
    for w in df.attrs.get("warnings", []):
        print(f"gsbench collect: warning: {w}", file=sys.stderr)
    bad = df.attrs.get("unreadable", [])
    if bad:
        print(f"gsbench collect: could not read {len(bad)} results.json file(s); each is a failed row with the "
              "reason, the other runs are collected", file=sys.stderr)
    out = write_collected(df, args.out or args.runs_dir)
    n_runs = df["run_id"].nunique()
    studies = sorted(
        {("standalone" if (s is None or s != s) else str(s)) for s in df.drop_duplicates("run_id")["study"]}
    )
    fmt = "Parquet" if out.suffix == ".parquet" else "CSV (pyarrow not installed)"
    print(f"collected {n_runs} runs, {len(df)} rows (studies: {', '.join(studies)}) -> {out} [{fmt}]")
    runs = df.drop_duplicates("run_id")
    n_dropped = int((runs["dropped"].fillna("") != "").sum())
    if n_dropped:
        print(f"{n_dropped} runs had settings dropped by the config resolver (column `dropped`)")
    return 0
