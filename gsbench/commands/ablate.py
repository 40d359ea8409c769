"""`gsbench ablate --grid GRID --out RUNS_DIR`: run an ablation / noise grid.

Re-running skips finished cells, resumes interrupted ones (stale `running` cells whose process is
gone) and leaves failed cells alone unless `--retry-failed`. `--status` prints progress only.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from gsbench import grids
from gsbench.config import parse_overrides, set_args
from gsbench.errors import InputError
from gsbench.grids.executors import make_executor
from gsbench.grids.runs_folder import owned_runs_folder


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--grid", help="a shipped grid name (see --list) or a grid YAML file")
    parser.add_argument("--out", type=Path, help="RUNS_DIR: one run folder per cell, shared scenes and priors cache")
    parser.add_argument("--set", dest="overrides", nargs="+", action="append", default=[], metavar="KEY=VALUE",
                        help="override config keys in every cell (e.g. train.iterations=30; repeatable); "
                        "may not be a grid axis")
    parser.add_argument("--executor", choices=["local", "submitit", "serial"], default="local",
                        help="local = process pool (--jobs), submitit = SLURM job arrays (--cluster), "
                        "serial = this process, one cell after another (debugging)")
    parser.add_argument("--jobs", type=int, default=1, help="local: worker processes (one cell each); "
                        "submitit/slurm: max concurrently running array tasks")
    parser.add_argument("--cluster", choices=["slurm", "local", "debug"], default="slurm",
                        help="submitit backend (local = subprocesses on this machine)")
    parser.add_argument("--slurm-partition", default=None)
    parser.add_argument("--timeout-min", type=int, default=None, help="submitit: job time limit in minutes")
    parser.add_argument("--cpus-per-task", type=int, default=None)
    parser.add_argument("--gpus-per-node", type=int, default=None)
    parser.add_argument("--retry-failed", action="store_true", help="re-run cells that failed before")
    parser.add_argument("--status", action="store_true", help="print the state of every cell and exit")
    parser.add_argument("--dry-run", action="store_true", help="list the cells (and their run ids) without running")
    parser.add_argument("--list", action="store_true", help="list the shipped grids")
    parser.add_argument("--force", action="store_true",
                        help="use an --out folder that holds files gsbench did not write there (they are left alone)")
    parser.add_argument("--no-shared-priors", action="store_true",
                        help="do not compute priors (and autoencoder fits) shared by several cells once before "
                             "the cells run")
    parser.add_argument("--no-progress", action="store_true")


def grid_from_args(args: argparse.Namespace):
    """The grid this command runs: the grid file with every --set applied to its base (None without --grid)."""
    extra = parse_overrides(set_args(args.overrides))
    if not args.grid:
        if extra:
            raise InputError("--set applies to the cells of a grid: give --grid too")
        return None
    return grids.load_grid(args.grid, extra_set=extra)


def run(args: argparse.Namespace) -> int:
    if args.list:
        for name in grids.shipped_grids():
            g = grids.load_grid(name)
            print(f"{name:28s} study={g.study:18s} cells={len(g.cells()):4d}  {g.description}")
        return 0
    if args.out is None:
        raise InputError("--out RUNS_DIR is required")
    grid = grid_from_args(args)
    if args.status:
        if not args.out.is_dir():
            raise InputError(f"{args.out}: runs folder not found")
        rows = grids.status_rows(args.out, grid)
        print(grids.format_status(rows))
        return 0
    if grid is None:
        raise InputError("--grid is required (a shipped name or a YAML file; --list shows the shipped ones)")
    if args.dry_run:
        for c in grid.cells():
            print(
                f"{c.method:10s} {c.scene.label:24s} seed={c.seed} " + " ".join(f"{k}={v}" for k, v in c.axes.items())
            )
        print(f"{len(grid.cells())} cells")
        return 0
    slurm = {"slurm_partition": args.slurm_partition, "timeout_min": args.timeout_min,
             "cpus_per_task": args.cpus_per_task, "gpus_per_node": args.gpus_per_node}
    if args.cluster != "slurm":
        slurm = {k: v for k, v in slurm.items() if not k.startswith("slurm_")}
    from concurrent.futures.process import BrokenProcessPool
    try:
        with owned_runs_folder(args.out, "gsbench ablate", force=args.force):   # one writer; refuses foreign files
            executor = make_executor(args.executor, jobs=args.jobs, folder=args.out / ".submitit",
                                     cluster=args.cluster, progress=not args.no_progress, **slurm)
            report = grids.run_grid(grid, args.out, executor, retry_failed=args.retry_failed,
                                    share_priors=not args.no_shared_priors, log=print)
    except BrokenProcessPool as e:
        print(f"gsbench ablate: a worker process died ({e}); finished cells are saved, re-run to resume "
              "the others (see --status)", file=sys.stderr)
        return 1
    rows = grids.planned_rows(report.planned)      # the cells this run planned (not re-planned)
    print(grids.format_status(rows))
    failed = [r for r in report.results if r and r.get("state") != "done"]
    for r in failed:
        print(f"failed: {r['run_dir']}: {r.get('error')}", file=sys.stderr)
    not_done = [r for r in rows if r["state"] != "done"]
    return 1 if not_done else 0
