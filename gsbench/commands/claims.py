"""`gsbench claims --out DIR`: run every grid the paper-claims table and its positive controls need
(resumable, the same executors and --jobs as `ablate`), then print the claims table and write the
report to DIR/report. `--quick` runs the same plan at tiny scale and two seeds (CI, smoke checks).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from gsbench import grids
from gsbench.errors import InputError
from gsbench.grids import claims_plan
from gsbench.grids.executors import make_executor
from gsbench.grids.planning import missing_scene_folders
from gsbench.grids.runs_folder import owned_runs_folder
from gsbench.grids.store import repo_store, reuse_published


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, required=True,
                        help="RUNS_DIR: one run folder per cell of every grid; the report goes to OUT/report")
    parser.add_argument("--quick", action="store_true",
                        help="the same plan at tiny scale and two seeds (minutes; checks the pipeline, not the claims)")
    parser.add_argument("--executor", choices=["local", "submitit", "serial"], default="local",
                        help="as in `gsbench ablate`")
    parser.add_argument("--jobs", type=int, default=1, help="as in `gsbench ablate`")
    parser.add_argument("--cluster", choices=["slurm", "local", "debug"], default="slurm",
                        help="submitit backend (as in `gsbench ablate`)")
    parser.add_argument("--retry-failed", action="store_true", help="re-run cells that failed before")
    parser.add_argument("--grids", nargs="+", default=None, metavar="GRID",
                        help="run only these grids of the plan (default: all; see --list)")
    parser.add_argument("--list", action="store_true", help="list the plan's grids and their cell counts")
    parser.add_argument("--force", action="store_true",
                        help="use an --out folder that holds files gsbench did not write there (they are left alone)")
    parser.add_argument("--store", type=Path, default=None, metavar="STORE",
                        help="reuse the cells published in this results store (default: the repository's "
                             "results/cpu when it exists; docs/publishing.md)")
    parser.add_argument("--no-store", action="store_true", help="reuse no published cell: train every cell")
    parser.add_argument("--no-progress", action="store_true")


def run(args: argparse.Namespace) -> int:
    known = claims_plan.plan_names()
    names = tuple(args.grids) if args.grids else None
    unknown = [n for n in names or () if n not in known]
    if unknown:
        raise InputError(f"--grids: {', '.join(unknown)} not in the claims plan ({', '.join(known)})")
    plan = claims_plan.plan_grids(quick=args.quick, names=names)
    if args.list:
        for g in plan:
            print(f"{g.name:28s} study={g.study:22s} cells={len(g.cells()):4d}  {g.description}")
        print(f"{sum(len(g.cells()) for g in plan)} cells in {len(plan)} grids")
        return 0
    with owned_runs_folder(args.out, "gsbench claims", force=args.force):
        return _run_plan(args, plan)


def _run_plan(args: argparse.Namespace, plan: list) -> int:
    """Every grid of the plan into args.out, then the report into args.out/report (under the folder's lock)."""
    from concurrent.futures.process import BrokenProcessPool

    from gsbench.reports.build import build_report  # lazy: start-up (cli loads all commands)
    executor = make_executor(args.executor, jobs=args.jobs, folder=args.out / ".submitit", cluster=args.cluster,
                             progress=not args.no_progress)
    store = None if args.no_store else args.store or repo_store()
    t0, not_done, runnable = time.time(), 0, []
    for g in plan:
        absent = missing_scene_folders(g)
        if absent:   # a capture that is not shipped (docs/real-captures.md): the rest of the plan still runs
            print(f"gsbench claims: grid {g.name} skipped: {absent[0]}", file=sys.stderr)
            not_done += len(g.cells())
            continue
        if store is not None:
            reuse_published(g, args.out, store, log=print)
        runnable.append(g)
    try:   # one dispatch for every grid: no core waits for a grid's last cell (grids.run_grids)
        reports = grids.run_grids(runnable, args.out, executor, retry_failed=args.retry_failed, log=print)
    except BrokenProcessPool as e:
        print(f"gsbench claims: a worker process died ({e}); finished cells are saved, re-run to resume",
              file=sys.stderr)
        return 1
    for rep in reports:
        rows = grids.planned_rows(rep.planned)
        not_done += sum(r["state"] != "done" for r in rows)
        for r in rep.results:
            if r and r.get("state") != "done":
                print(f"failed: {r['run_dir']}: {r.get('error')}", file=sys.stderr)
    print(f"gsbench claims: {len(plan)} grids in {time.time() - t0:.0f} s" + (" (quick)" if args.quick else ""))
    summary = build_report(args.out, args.out / "report", progress=not args.no_progress, force=args.force)
    for t in ("paper_claims", "claims_controls"):
        if t in summary.tables:
            print((summary.out_dir / "tables" / f"{t}.md").read_text(encoding="utf-8"))
    print(f"Report: {summary.index}")
    if not_done:
        print(f"gsbench claims: {not_done} cells not done (see `gsbench ablate --status --out {args.out}`)",
              file=sys.stderr)
    return 1 if not_done else 0
