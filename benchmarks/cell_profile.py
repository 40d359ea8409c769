"""Benchmark: where a claims cell's time goes, phase by phase, sampled with py-spy.

    .venv/bin/python benchmarks/cell_profile.py --grid control_sem-cpu [--seeds 0] [--tree DIR ...]
                                                [--rate 40] [--work DIR] [--json out.json]

For each checkout (`--tree`, each with its own `.venv`; default this one) it runs that checkout's grid
file trimmed to `--seeds` with `gsbench ablate --executor local --jobs 1` under
`py-spy record --subprocesses --format raw`, and sorts every sample of every process into one phase
of a cell (the PHASES rules, first match, on the sample's Python stack). It prints the seconds of
samples per phase and checkout, divided by the number of cells: the profiler's own overhead is in
them, so compare checkouts measured by the same command, not with cell_overhead.py's wall times.
py-spy is not a gsbench dependency: `pip install py-spy` (it samples other processes, which some
containers forbid). Run on an otherwise idle machine.
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cell_overhead import ablate_argv, trimmed_grid  # noqa: E402  (a script beside this one)

# (phase, substrings: a sample belongs to the phase when its stack holds any of them), first match wins
PHASES: list[tuple[str, tuple[str, ...]]] = [
    ("periodic evaluations", ("periodic_eval", "_eval (gsbench/runs/training.py")),
    ("evaluation: decoder", ("decode (gsbench/train/autoencoder.py",)),
    ("evaluation: text cosines and pixel norms", ("_cosines (gsbench/evaluation/segmentation.py",)),
    ("evaluation: the rest", ("gsbench/evaluation/", "evaluate_run")),
    # the autoencoder: a cell's own fit or restore, and a grid's shared fits
    ("autoencoder fit or restore", ("gsbench/train/autoencoder.py", "semantic_targets.py")),
    ("priors", ("gsbench/priors/", "priors_share.py")),
    ("raster backward", ("_raster_backward", "raster_backward")),
    ("raster forward", ("_raster_forward", "raster_forward")),
    ("projection, forward and backward", ("cpu_projection.py", "_Projection", "project_gaussians")),
    ("losses", ("gsbench/train/losses", "ssim_cpu.py")),
    ("optimiser (Adam)", ("gsbench/train/adam.py",)),
    ("the rest of the steps", ("gsbench/train/", "gsbench/runs/training.py")),
    ("process start and imports", ("_find_and_load",)),
]
OTHER = "other (run folder files, config, waiting)"
FORKSERVER = "forkserver: imports and kernel loading"


def phase_of(stack: str) -> str:
    """The phase of one sample's stack (frames joined by ';'). A worker's stack starts in the
    forkserver's code too, below `_serve_one`; the server's own samples do not pass through it."""
    if "multiprocessing/forkserver.py" in stack and "_serve_one" not in stack:
        return FORKSERVER
    for name, marks in PHASES:
        if any(m in stack for m in marks):
            return name
    return OTHER


def read_raw(path: Path, rate: float) -> Counter:
    """Seconds of samples per phase from py-spy's raw (collapsed) output: 'frames count' per line."""
    seconds: Counter = Counter()
    for line in path.read_text().splitlines():
        stack, _, count = line.rpartition(" ")
        if stack and count.isdigit():
            seconds[phase_of(stack)] += int(count) / rate
    return seconds


def profile_tree(tree: Path, grid: str, seeds: list[int], work: Path, rate: float, py_spy: str) -> dict:
    """Run the trimmed grid under py-spy with `tree`'s gsbench; seconds per phase and the cell count."""
    grid_file = trimmed_grid(tree, grid, seeds, work)
    out = work / "py-spy.txt"
    subprocess.run([py_spy, "record", "--subprocesses", "--rate", str(int(rate)), "--format", "raw", "--output",
                    str(out), "--", *ablate_argv(tree, grid_file, work / "runs", 1)], check=True)
    cells = len(list((work / "runs").glob("*/results.json")))
    return {"tree": str(tree), "cells": cells, "seconds": dict(read_raw(out, rate))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--grid", required=True)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--tree", type=Path, nargs="+", default=[Path(__file__).resolve().parents[1]])
    ap.add_argument("--rate", type=float, default=40.0, help="py-spy samples a second")
    ap.add_argument("--work", type=Path, default=Path("cell_profile_work"))
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    py_spy = shutil.which("py-spy")
    if py_spy is None:
        print("cell_profile.py: py-spy is not on PATH (pip install py-spy)", file=sys.stderr)
        return 2
    results = [profile_tree(t.resolve(), args.grid, args.seeds, args.work / f"tree{i}", args.rate, py_spy)
               for i, t in enumerate(args.tree)]
    names = [FORKSERVER] + [p for p, _ in PHASES] + [OTHER]
    print("seconds of samples per cell")
    print(f"{'phase':45s}" + "".join(f" {Path(r['tree']).name[-14:]:>14s}" for r in results))
    for name in names:
        per_cell = [r["seconds"].get(name, 0.0) / max(1, r["cells"]) for r in results]
        print(f"{name[:45]:45s}" + "".join(f" {v:14.2f}" for v in per_cell))
    print(f"{'all':45s}" + "".join(f" {sum(r['seconds'].values()) / max(1, r['cells']):14.2f}" for r in results))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
