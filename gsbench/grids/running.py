"""Running: one cell (train, then evaluate, in its run folder) and a whole grid through an executor."""
from __future__ import annotations

import copy
import logging
import os
import socket
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from gsbench import rundir
from gsbench.evaluation import evaluate_run
from gsbench.grids.executors import apply_thread_budget
from gsbench.grids.failed import write_failed_results
from gsbench.grids.grid_file import Grid
from gsbench.grids.liveness import CELL_FILE, CELL_STATUS_FILE, HEARTBEAT_S, cell_state, read_cell_status
from gsbench.grids.planning import PlannedCell, plan, write_manifest
from gsbench.grids.priors_share import shared_priors
from gsbench.runlock import RunLock, RunLockedError
from gsbench.runs import train_run
from gsbench.store import write_json_atomic
from gsbench.train.render_backend import prebuild_for

log_ = logging.getLogger(__name__)


class _Heartbeat:
    """Refresh cell_status.json every HEARTBEAT_S seconds while a cell runs."""

    def __init__(self, run_dir: Path, status: dict) -> None:
        self.run_dir, self.status = run_dir, status
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def _loop(self) -> None:
        while not self._stop.wait(HEARTBEAT_S):
            self.status["heartbeat"] = time.time()
            try:
                write_json_atomic(self.run_dir / CELL_STATUS_FILE, self.status)
            except OSError:
                pass

    def __enter__(self) -> "_Heartbeat":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def run_cell(spec: dict) -> dict:
    """Train then evaluate one cell in its run folder; never raises for a failing cell (the failure
    is written to cell_status.json and returned), so one bad cell does not stop a grid.

    The cell holds the folder's writer lock for train + eval; a stale lock (its holder was killed)
    is taken over, a live one leaves the cell alone (state "locked", nothing written)."""
    run_dir = Path(spec["run_dir"])
    try:
        with RunLock(run_dir, command=f"gsbench ablate cell {run_dir.name} (pid {os.getpid()})"):
            return _run_cell_locked(spec, run_dir)
    except RunLockedError as e:
        log_.warning("%s", e)
        return {"run_dir": str(run_dir), "state": "locked", "error": str(e), "wall_s": 0.0}


def _run_cell_locked(spec: dict, run_dir: Path) -> dict:
    prev = read_cell_status(run_dir)
    status = {"state": "running", "pid": os.getpid(), "host": socket.gethostname(), "started": time.time(),
              "heartbeat": time.time(), "attempt": int(prev.get("attempt", 0)) + 1, "phase": "train",
              "resumed": (run_dir / rundir.CHECKPOINT).exists()}
    write_json_atomic(run_dir / CELL_STATUS_FILE, status)
    cell_json = run_dir / CELL_FILE
    if not cell_json.exists():
        write_json_atomic(cell_json, {k: v for k, v in spec.items() if k != "config"})
    t0 = time.time()
    try:
        with _Heartbeat(run_dir, status):
            _train_and_evaluate(spec, run_dir, status)
        status.update(state="done", finished=time.time(), wall_s=time.time() - t0, phase="done")
        write_json_atomic(run_dir / CELL_STATUS_FILE, status)
    except Exception as e:  # recorded per cell; the grid goes on
        status.update(state="failed", finished=time.time(), wall_s=time.time() - t0,
                      error=f"{type(e).__name__}: {e}", traceback=traceback.format_exc())
        try:
            write_failed_results(spec, run_dir, status)
        except Exception as e2:  # the failure itself is still recorded in cell_status.json
            status["results_error"] = f"could not write the failed results.json: {type(e2).__name__}: {e2}"
        write_json_atomic(run_dir / CELL_STATUS_FILE, status)
    return {"run_dir": str(run_dir), "state": status["state"], "error": status.get("error"),
            "wall_s": status["wall_s"]}


def _train_and_evaluate(spec: dict, run_dir: Path, status: dict) -> None:
    status["torch_threads"] = apply_thread_budget()
    train_run(copy.deepcopy(spec["config"]), spec["scene_path"], run_dir, progress=False)
    status["phase"] = "eval"
    write_json_atomic(run_dir / CELL_STATUS_FILE, status)
    evaluate_run(run_dir, progress=False)


# ----------------------------------------------------------------------------- running a grid
@dataclass
class GridReport:
    planned: list[PlannedCell]
    states: dict[str, str]             # run_id -> state before running
    dispatched: list[str]
    results: list[dict]


def classify(planned: list[PlannedCell]) -> dict[str, str]:
    return {pc.run_id: cell_state(pc.run_dir) for pc in planned if pc.run_id}


def run_grid(grid: Grid, runs_dir: Path, executor: Any, retry_failed: bool = False,
             log: Callable[[str], None] = log_.info, share_priors: bool = True) -> GridReport:
    """Plan the grid, skip finished cells, compute shared priors once, dispatch the remaining cells
    through `executor` (anything with `map(fn, items) -> list`), and return what happened: `run_grids`
    with one grid."""
    return run_grids([grid], runs_dir, executor, retry_failed, log, share_priors)[0]


def run_grids(grid_list: list[Grid], runs_dir: Path, executor: Any, retry_failed: bool = False,
              log: Callable[[str], None] = log_.info, share_priors: bool = True) -> list[GridReport]:
    """Several grids into one runs folder as one dispatch (gsbench claims): every grid is planned first,
    the priors and fits their pending cells share are computed once, and all pending cells go to the
    executor as one list, so a worker that finishes one grid's last cell starts the next grid's first
    instead of idling until the grid is done. A cell that two grids plan (the same run id) runs once and
    is in both reports. One GridReport per grid, in order.

    Holds RUNS_DIR's writer lock throughout: a second grid into the same folder fails at once (a
    RunLockedError naming this one); the cells lock their own run folders."""
    runs_dir = Path(runs_dir)
    with RunLock(runs_dir, what="runs folder"):
        parts = [_pending(grid, runs_dir, retry_failed, log) for grid in grid_list]
        todo = list({pc.run_id: pc for _, _, pending in parts for pc in pending}.values())
        if todo:    # gsplat's one-time CUDA build here, not in several workers at once
            prebuild_for(pc.config for pc in todo)
        if todo and share_priors:
            shared_priors(todo, executor, log)
        ran = executor.map(run_cell, [pc.spec() for pc in todo]) if todo else []
        results = dict(zip((pc.run_id for pc in todo), ran))
        return [GridReport(planned, states, [pc.run_id for pc in pending], [results[pc.run_id] for pc in pending])
                for planned, states, pending in parts]


def _pending(grid: Grid, runs_dir: Path, retry_failed: bool,
             log: Callable[[str], None]) -> tuple[list[PlannedCell], dict[str, str], list[PlannedCell]]:
    """The grid's planned cells (manifest written), their states, and those to run now."""
    planned = plan(grid, runs_dir)
    states = classify(planned)
    write_manifest(grid, runs_dir, planned)
    todo = []
    for pc in planned:
        st = states[pc.run_id]
        if st == "done":
            continue
        if st == "running":
            log(f"cell {pc.run_id}: running in another process (heartbeat fresh); not started again")
            continue
        if st == "failed" and not retry_failed:
            continue
        todo.append(pc)
    counts = {s: list(states.values()).count(s) for s in ("done", "failed", "running", "stale", "pending")}
    log(f"grid {grid.name}: {len(planned)} cells; " + ", ".join(f"{k} {v}" for k, v in counts.items() if v)
        + f"; dispatching {len(todo)}" + ("" if retry_failed or not counts["failed"]
                                          else " (failed cells skipped; use --retry-failed)"))
    return planned, states, todo
