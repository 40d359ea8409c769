"""Benchmark: where a claims cell's wall time goes, and the same cells on another gsbench checkout.

    .venv/bin/python benchmarks/cell_overhead.py --grid control_sem-cpu [--seeds 0] [--tree DIR ...]
                                                 [--jobs N] [--work DIR] [--json out.json]

For each checkout (`--tree`, default: this one; each needs its own `.venv` with gsbench installed
from it) it copies that checkout's grid file of the claims plan with only `--seeds`, runs it with
`gsbench ablate --executor local --jobs N` (a process per cell, as `gsbench claims` runs the plan; N = 1 by
default, so the phases are those of a cell alone on the machine)
and reads every cell's phases from its run folder: the cell's wall time (cell_status.json), training
(train_summary.json `train_s`: priors, data and optimisation), evaluation (results.json `eval_s`)
and the rest (process start, imports, config, run folder files). It prints one row per cell, the
per-checkout means, the whole command's wall time (scene, shared priors and cells), the cells it finished
per hour, and each checkout's ratio of command time to the first's. Run it
on an otherwise idle machine: the times are wall times. The cells' numbers are not compared here
(`gsbench verify` does that); the first checkout is the baseline.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import time
from pathlib import Path

import yaml


def trimmed_grid(tree: Path, grid: str, seeds: list[int], work: Path) -> Path:
    """`tree`'s own file of grid `grid` with only `seeds` (and no later seeds), written into `work`."""
    raw = yaml.safe_load((tree / "gsbench" / "grids" / f"{grid}.yaml").read_text())
    raw["seeds"] = seeds
    raw.pop("later_seeds", None)
    work.mkdir(parents=True, exist_ok=True)
    grid_file = work / f"{grid}.yaml"
    grid_file.write_text(yaml.safe_dump(raw, sort_keys=False))
    return grid_file


def ablate_argv(tree: Path, grid_file: Path, runs: Path, jobs: int) -> list[str]:
    """`tree`'s `gsbench ablate` of `grid_file` into `runs`, a process per cell, `jobs` at a time."""
    return [str(tree / ".venv" / "bin" / "gsbench"), "-q", "ablate", "--grid", str(grid_file), "--out", str(runs),
            "--executor", "local", "--jobs", str(jobs), "--no-progress"]


def run_tree(tree: Path, grid: str, seeds: list[int], work: Path, jobs: int = 1) -> dict:
    """Run the trimmed grid with `tree`'s gsbench; its per-cell phases and the command's wall time."""
    grid_file = trimmed_grid(tree, grid, seeds, work)
    t0 = time.perf_counter()
    subprocess.run(ablate_argv(tree, grid_file, work / "runs", jobs), check=True)
    wall = time.perf_counter() - t0
    cells = []
    for status in sorted((work / "runs").glob("*/cell_status.json")):
        run = status.parent
        cell_s = json.loads(status.read_text()).get("wall_s")
        train_s = json.loads((run / "train_summary.json").read_text()).get("train_s")
        eval_s = (json.loads((run / "results.json").read_text()).get("timings") or {}).get("eval_s")
        if None in (cell_s, train_s, eval_s):
            continue
        cells.append({"run": run.name, "cell_s": cell_s, "train_s": train_s, "eval_s": eval_s,
                      "other_s": cell_s - train_s - eval_s})
    return {"tree": str(tree), "command_s": wall, "cells": cells}


def summary(result: dict) -> dict:
    """Per-phase means over the cells of one checkout."""
    keys = ("cell_s", "train_s", "eval_s", "other_s")
    cells = result["cells"]
    return {k: statistics.fmean(c[k] for c in cells) if cells else float("nan") for k in keys}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--grid", required=True, help="a grid of the claims plan, e.g. control_sem-cpu")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--tree", type=Path, nargs="+", default=[Path(__file__).resolve().parents[1]],
                    help="gsbench checkouts, each with its .venv; the first is the baseline")
    ap.add_argument("--jobs", type=int, default=1, help="cells at a time (gsbench claims --jobs)")
    ap.add_argument("--work", type=Path, default=Path("cell_overhead_work"))
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    results = [run_tree(t.resolve(), args.grid, args.seeds, args.work / f"tree{i}", args.jobs)
               for i, t in enumerate(args.tree)]
    print(f"jobs: {args.jobs}")
    print(f"{'checkout':40s} {'cells':>5s} {'cell s':>8s} {'train s':>8s} {'eval s':>8s} {'other s':>8s} "
          f"{'command s':>9s} {'cells/h':>7s} {'ratio':>6s}")
    base = results[0]["command_s"]
    for r in results:
        for c in r["cells"]:
            print(f"  {c['run']:38s} {'':5s} {c['cell_s']:8.1f} {c['train_s']:8.1f} {c['eval_s']:8.1f} "
                  f"{c['other_s']:8.1f}")
        s = summary(r)
        print(f"{r['tree'][-40:]:40s} {len(r['cells']):5d} {s['cell_s']:8.1f} {s['train_s']:8.1f} {s['eval_s']:8.1f} "
              f"{s['other_s']:8.1f} {r['command_s']:9.1f} {3600 * len(r['cells']) / r['command_s']:7.1f} "
              f"{r['command_s'] / base:6.2f}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
