"""Run as many cells of the claims plan as fit in a time budget on a lent GPU machine, and publish
them into the results store results/gpu (docs/training.md, "First run on a GPU").

    scripts/gpu_claims.sh --wheels .whl --minutes 9 --jobs 16 --log $OUT/gpu_claims.log
    scripts/gpu_claims.sh --wheels .whl --dry-run        # print the steps, run nothing

The steps, all offline (pip gets --no-index; nothing is downloaded):
1. install the carried wheels (gsplat, pycolmap, ...) and this checkout (`pip install --no-deps -e .`);
2. check that torch sees CUDA, then build gsplat's CUDA extension once (`gsbench doctor --build-gsplat`);
3. write each claims grid with `backend: gsplat` added to its base.set into RUNS/_grids (same grid name,
   own run ids: a cell that cannot render on gsplat fails instead of moving to another renderer);
4. run the grids in `--lanes` lanes side by side, each grid a `gsbench ablate --jobs J` into RUNS/<grid>
   (the lanes' J sum to --jobs; every worker shares the one GPU). Cells already in the store are put
   into the runs folder first and not trained again. At the cell deadline each running ablate gets
   SIGINT (as Ctrl-C), then SIGKILL after a grace: cells under way are resumable, grids not started
   are left for the next run;
5. publish each grid's finished cells with `gsbench publish RUNS/<grid> --to STORE --grids FILE`;
6. log the cells finished per minute and write a summary JSON beside the log.

`reuse RUNS GRID_FILE STORE` (used by step 4) puts the published cells of one grid into its runs folder.
"""
from __future__ import annotations

import argparse
import ast
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BACKEND = "gsplat"
OFFLINE_ENV = {"PIP_NO_INDEX": "1", "PIP_DISABLE_PIP_VERSION_CHECK": "1", "HF_HUB_OFFLINE": "1",
               "TRANSFORMERS_OFFLINE": "1", "PYTHONUNBUFFERED": "1"}
CUDA_CHECK = "import sys, torch; sys.exit(0 if torch.cuda.is_available() else 3)"


def claims_grids(root: Path = ROOT) -> list[str]:
    """The claims plan's grids in running order, read from the study table
    (methods/gaussiands/study_table.py: each `Study(...)`'s literal `claims_grids` and `kind`, paper
    studies then controls, as declared) without importing gsbench (the orchestrator starts before gsbench
    is installed)."""
    path = root / "methods" / "gaussiands" / "study_table.py"
    found: dict[str, list[str]] = {"paper": [], "control": []}
    calls = [n for n in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
             if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "Study"]
    for call in sorted(calls, key=lambda n: (n.lineno, n.col_offset)):
        kw = {k.arg: k.value for k in call.keywords}
        kind = ast.literal_eval(kw["kind"]) if "kind" in kw else "paper"
        if "claims_grids" in kw and kind in found:
            found[kind] += list(ast.literal_eval(kw["claims_grids"]))
    if not found["paper"]:
        raise SystemExit(f"{path}: no Study(...) with a literal claims_grids found")
    return found["paper"] + found["control"]


def split_jobs(jobs: int, lanes: int) -> list[int]:
    """--jobs over the lanes, the first lanes one more when it does not divide; never a lane of 0."""
    lanes = max(1, min(lanes, jobs))
    return [jobs // lanes + (k < jobs % lanes) for k in range(lanes)]


def install_commands(py: str, wheels: Path) -> list[list[str]]:
    whl = sorted(str(p) for p in Path(wheels).glob("*.whl"))
    if not whl:
        raise SystemExit(f"{wheels}: no .whl files to install (carry the wheels folder; docs/training.md)")
    pip = [py, "-m", "pip", "install", "--no-index", "--find-links", str(wheels), "--no-deps", "--no-cache-dir"]
    return [pip + whl, pip + ["--no-build-isolation", "-e", str(ROOT)]]


def gsbench(py: str, *args: str) -> list[str]:
    return [py, "-m", "gsbench.cli", *args]


def write_gpu_grid(name: str, folder: Path, root: Path = ROOT, backend: str = BACKEND) -> Path:
    """The shipped grid `name` with `backend` added to its base.set, as folder/<name>.yaml (atomic)."""
    import yaml
    raw = yaml.safe_load((root / "gsbench" / "grids" / f"{name}.yaml").read_text(encoding="utf-8"))
    base = raw.setdefault("base", {})
    base["set"] = {**(base.get("set") or {}), "backend": backend}
    folder.mkdir(parents=True, exist_ok=True)
    out, tmp = folder / f"{name}.yaml", folder / f".{name}.yaml.tmp"
    tmp.write_text(yaml.safe_dump(raw, sort_keys=False), encoding="utf-8")
    os.replace(tmp, out)
    return out


def cell_states(runs_dir: Path) -> list[dict]:
    """cell_status.json of every cell folder in a grid's runs folder (unreadable ones left out)."""
    out = []
    for p in sorted(Path(runs_dir).glob("*/cell_status.json")):
        try:
            st = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(st, dict):
            out.append(st)
    return out


def per_minute(finished: list[float], start: float) -> list[int]:
    """Cells finished in each whole minute after `start` (minute 1 first)."""
    counts: list[int] = []
    for t in sorted(finished):
        k = max(0, int((t - start) // 60))
        counts += [0] * (k + 1 - len(counts))
        counts[k] += 1
    return counts


class Run:
    """One invocation: its options, the clock, the log, and what happened to each grid."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.t0 = time.monotonic()
        self.end = self.t0 + args.minutes * 60.0
        self.cell_deadline = self.end - args.reserve_s
        self.env = {**os.environ, **OFFLINE_ENV, "MAX_JOBS": os.environ.get("MAX_JOBS", str(os.cpu_count() or 1)),
                    "TORCH_CUDA_ARCH_LIST": os.environ.get("TORCH_CUDA_ARCH_LIST", "9.0")}
        self.grids: dict[str, dict] = {}
        self.lock = threading.Lock()
        self.log_path = Path(args.log) if args.log else Path(args.out) / "gpu_claims.log"

    def log(self, line: str) -> None:
        text = f"[{time.monotonic() - self.t0:7.1f} s] {line}"
        with self.lock:
            print(text, flush=True)
            if not self.args.dry_run:
                self.log_path.parent.mkdir(parents=True, exist_ok=True)
                with open(self.log_path, "a", encoding="utf-8") as f:
                    f.write(text + "\n")

    def call(self, cmd: list[str], deadline: float | None = None) -> tuple[int, bool]:
        """Run cmd in its own process group; at `deadline` SIGINT the group, SIGKILL it after the grace.
        Returns (exit status, whether it was stopped at the deadline)."""
        self.log("$ " + " ".join(cmd))
        if self.args.dry_run:
            return 0, False
        p = subprocess.Popen(cmd, env=self.env, start_new_session=True)
        try:
            return p.wait(timeout=None if deadline is None else max(0.0, deadline - time.monotonic())), False
        except subprocess.TimeoutExpired:
            pass
        self.log(f"pid {p.pid}: budget reached, SIGINT to its process group")
        _signal_group(p.pid, signal.SIGINT)
        try:
            return p.wait(timeout=self.args.grace_s), True
        except subprocess.TimeoutExpired:
            self.log(f"pid {p.pid}: still running after {self.args.grace_s:.0f} s, SIGKILL to its process group")
            _signal_group(p.pid, signal.SIGKILL)
            return p.wait(), True


def _signal_group(pid: int, sig: int) -> None:
    try:
        os.killpg(pid, sig)
    except ProcessLookupError:
        pass


def prepare(run: Run) -> bool:
    """Install, check CUDA, build gsplat; False (logged) when any step fails."""
    a, py = run.args, run.args.python
    steps = [] if a.wheels is None else install_commands(py, Path(a.wheels))
    steps += [[py, "-c", CUDA_CHECK], gsbench(py, "doctor", "--build-gsplat")]
    for cmd in steps:
        rc, _ = run.call(cmd)
        if rc != 0:
            why = "torch sees no CUDA device" if cmd[1] == "-c" else f"exit status {rc}"
            run.log(f"stopped before any cell: {why}")
            return False
    return True


def run_grid(run: Run, name: str, grid_file: Path, jobs: int, lane: int) -> None:
    """Reuse the store's cells of one grid, then its ablate until the cell deadline."""
    a = run.args
    runs = Path(a.out) / name
    info = run.grids[name]
    if (Path(a.store) / name).is_dir():
        rc, _ = run.call([a.python, str(Path(__file__).resolve()), "reuse", str(runs), str(grid_file), str(a.store)],
                         run.cell_deadline)
        info["reuse_rc"] = rc
    info.update(lane=lane, jobs=jobs, started=time.time())
    run.log(f"lane {lane}: {name}, --jobs {jobs}")
    rc, stopped = run.call(gsbench(a.python, "ablate", "--grid", str(grid_file), "--out", str(runs),
                                   "--jobs", str(jobs), "--no-progress"), run.cell_deadline)
    info.update(ablate_rc=rc, stopped_at_budget=stopped, ended=time.time())


def lane_worker(run: Run, lane: int, jobs: int, queue: list[tuple[str, Path]]) -> None:
    while True:
        with run.lock:
            if not queue:
                return
            name, grid_file = queue.pop(0)
        left = run.cell_deadline - time.monotonic()
        if left < run.args.min_start_s:
            run.log(f"lane {lane}: {name} not started ({max(0.0, left):.0f} s left < {run.args.min_start_s:.0f} s); "
                    "left for the next run")
            continue
        run_grid(run, name, grid_file, jobs, lane)


def run_cells(run: Run, grid_files: dict[str, Path]) -> tuple[float, float]:
    """The lanes, side by side, over the grids in plan order; the wall-clock start and end of the cell phase."""
    a = run.args
    for name in grid_files:
        run.grids[name] = {"grid_file": str(grid_files[name])}
    queue = list(grid_files.items())
    split = split_jobs(a.jobs, a.lanes)
    run.log(f"cells: {len(queue)} grids, {len(split)} lanes with --jobs {split} (sum {sum(split)}), "
            f"{run.cell_deadline - time.monotonic():.0f} s until the cell deadline")
    run.log("grids in this order, each taken by the first free lane: " + ", ".join(n for n, _ in queue))
    start = time.time()
    threads = [threading.Thread(target=lane_worker, args=(run, k, j, queue)) for k, j in enumerate(split)]
    for t in threads:
        t.start()
        if a.dry_run:          # one lane after the other, so the printed plan reads in order
            t.join()
    tick = time.monotonic() + 60.0
    while any(t.is_alive() for t in threads):
        time.sleep(0.2)
        if time.monotonic() >= tick:   # the running count, so a killed command still leaves a log
            tick += 60.0
            done = sum(s.get("state") == "done" for n in run.grids for s in cell_states(Path(a.out) / n))
            run.log(f"progress: {done} cells done in the runs folders")
    return start, time.time()


def publish_all(run: Run) -> int:
    """Publish every grid that has a finished cell into the store, one call per grid (all or nothing each,
    so one stopped at the end of the budget writes nothing); the number that failed or did not run."""
    a, failures = run.args, 0
    for name, info in run.grids.items():
        done = [s for s in cell_states(Path(a.out) / name) if s.get("state") == "done"]
        info["done"] = len(done)
        if not done and not a.dry_run:
            continue
        if time.monotonic() >= run.end:     # the budget is spent: publish these by hand, or re-run the script
            run.log(f"{name}: {len(done)} finished cells not published (the budget is spent)")
            info["publish_rc"], failures = "skipped", failures + 1
            continue
        rc, _ = run.call(gsbench(a.python, "publish", str(Path(a.out) / name), "--to", str(a.store),
                                 "--grids", info["grid_file"]), run.end + a.grace_s)
        info["publish_rc"] = rc
        failures += rc != 0
    return failures


def summarise(run: Run, cell_start: float, cell_end: float) -> dict:
    """Cells per minute of the cell phase (cells trained by this run; reused ones apart), logged."""
    a = run.args
    trained, reused, unfinished = [], 0, 0
    for name in run.grids:
        for st in cell_states(Path(a.out) / name):
            if st.get("state") != "done":
                unfinished += 1
            elif "published" in st:
                reused += 1
            elif float(st.get("finished") or 0) >= cell_start:
                trained.append(float(st["finished"]))
    counts = per_minute(trained, cell_start)
    for k, n in enumerate(counts):
        run.log(f"minute {k + 1}: {n} cells ({sum(counts[:k + 1])} so far)")
    minutes = max(0.0, cell_end - cell_start) / 60.0
    rate = len(trained) / minutes if minutes > 0 else 0.0
    not_started = [n for n, i in run.grids.items() if "started" not in i]
    run.log(f"trained {len(trained)} cells in a cell phase of {minutes:.2f} min ({rate:.1f} a minute; "
            f"{(time.monotonic() - run.t0) / 60:.2f} min since the start); reused {reused} from the store; "
            f"{unfinished} cell folders not done (resumable); grids not started: {not_started or 'none'}")
    return {"trained": len(trained), "per_minute": counts, "cells_per_minute": rate, "reused": reused,
            "cell_phase_min": minutes,
            "unfinished": unfinished, "not_started": not_started, "grids": run.grids,
            "jobs": a.jobs, "lanes": split_jobs(a.jobs, a.lanes), "store": str(a.store)}


def orchestrate(args: argparse.Namespace) -> int:
    run = Run(args)
    names = args.grids or claims_grids()
    run.log(f"gpu_claims: {len(names)} grids, budget {args.minutes:.1f} min (cells until "
            f"{run.cell_deadline - run.t0:.0f} s), --jobs {args.jobs} in {args.lanes} lanes, store {args.store}"
            + (" (dry run: nothing is run)" if args.dry_run else ""))
    if not prepare(run):
        return 1
    folder = Path(args.out) / "_grids"
    grid_files = {n: (folder / f"{n}.yaml" if args.dry_run else write_gpu_grid(n, folder)) for n in names}
    cell_start, cell_end = run_cells(run, grid_files)
    failures = publish_all(run)
    summary = summarise(run, cell_start, cell_end)
    if not args.dry_run:
        out = run.log_path.with_suffix(".json")
        tmp = out.with_name(f".{out.name}.tmp")
        tmp.write_text(json.dumps(summary, indent=1, sort_keys=True), encoding="utf-8")
        os.replace(tmp, out)
    return 1 if failures else 0


def reuse(argv: list[str]) -> int:
    """`reuse RUNS GRID_FILE STORE`: the store's cells of one grid into its runs folder, as finished cells."""
    from gsbench.grids.grid_file import load_grid  # lazy: runs after the install step only
    from gsbench.grids.runs_folder import owned_runs_folder  # lazy: as above
    from gsbench.grids.store import reuse_published  # lazy: as above
    if len(argv) != 3:
        raise SystemExit("usage: gpu_claims.py reuse RUNS GRID_FILE STORE")
    runs, grid = Path(argv[0]), load_grid(argv[1])
    with owned_runs_folder(runs, "scripts/gpu_claims.py reuse"):
        reuse_published(grid, runs, Path(argv[2]), log=print)
    return 0


def parse_args(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--wheels", type=Path, default=None, help="folder of carried wheels (omit: install nothing)")
    p.add_argument("--out", type=Path, default=ROOT / "runs" / "gpu", help="RUNS: one runs folder per grid")
    p.add_argument("--store", type=Path, default=ROOT / "results" / "gpu", help="the results store to publish into")
    p.add_argument("--minutes", type=float, default=9.0, help="wall budget of the whole script")
    p.add_argument("--reserve-s", type=float, default=75.0, help="seconds kept after the cells for publishing")
    p.add_argument("--grace-s", type=float, default=20.0, help="SIGINT to SIGKILL at the deadline")
    p.add_argument("--min-start-s", type=float, default=40.0, help="do not start a grid with less left")
    p.add_argument("--jobs", type=int, default=16, help="GPU worker processes in all (one cell each)")
    p.add_argument("--lanes", type=int, default=2, help="grids run side by side; --jobs is split over them")
    p.add_argument("--grids", nargs="+", default=None, help="these grids of the claims plan (default: all)")
    p.add_argument("--python", default=sys.executable, help="the interpreter that runs pip and gsbench")
    p.add_argument("--log", type=Path, default=None, help="log file (default RUNS/gpu_claims.log); summary beside it")
    p.add_argument("--dry-run", action="store_true", help="print the steps and run nothing")
    a = p.parse_args(argv)
    if a.jobs < 1 or a.lanes < 1 or a.minutes <= 0:
        p.error("--jobs and --lanes must be >= 1 and --minutes > 0")
    return a


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["reuse"]:
        return reuse(argv[1:])
    return orchestrate(parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
