"""Ablation grids: parse and validate grid files, expand them into cells, run cells with status.

A grid file (YAML) names a base config, scenes, seeds and axes:

    study: depth_formulation          # a study name from gsbench.store (or any name for your own grids)
    base:
      method: gaussiands
      preset: cpu-small               # gsbench/configs/<preset>.yaml, or null
      set: {train.iterations: 300}    # overrides applied to every cell (dotted keys)
    scenes: [tabletop-small]          # synthetic preset names or scene folders (${ENV} expanded)
    seeds: [0]
    mode: product                     # product | zip (for `axes`)
    axes:
      gaussiands.depth_formulation: [none, raw_l1, minmax, scale_shift, pearson]
    sweeps: []                        # optional extra axis blocks, each {mode, axes}; cells are unioned
    extra_cells:                      # optional single cells, e.g. a reference: [{method: vanilla}]
      - {method: vanilla}

Every axis key must be a key of gsbench/configs/default.yaml (a leaf of the tree); unknown keys are
an InputError with the closest valid names. A cell = (scene, seed, overrides); its run folder is
RUNS_DIR/<run_id>, run_id = gsbench.config.run_id(resolved config, scene fingerprint), so a re-run
finds finished cells. `grid` (recorded in config and results) maps EVERY axis key of the grid to the
value the cell's resolved config has there, so tables always have the same columns.

Cell execution state lives in RUNS_DIR/<run_id>/cell_status.json (the run's own status.json belongs
to training): state pending|running|done|failed, pid, host, heartbeat (unix seconds) for stale
detection, attempt count, error and traceback. A cell is done when that file says done and
results.json exists and is not a failure record: a failed cell also gets a results.json with status
"failed", null metrics and the error as each metric's reason in `skipped` (so reports show "n/a (run failed)" instead
of "no run"); it stays failed on a re-run and `--retry-failed` runs it again.

Modules, one job each: grid_file (grid files -> Grid, cells), planning (scenes, cell configs, run ids,
manifest), liveness (cell_status.json, pid and heartbeat checks), running (a cell, a grid),
priors_share (priors shared by several cells), failed (results.json of a failed cell), status
(the status table), executors (local pool, serial, submitit), claims_plan (the grids `gsbench
claims` runs, and their --quick variant), store (the published results store), verify (re-running
published cells).
"""
from gsbench.grids.failed import write_failed_results

from gsbench.grids.grid_file import (GRID_DIR, STUDIES, Cell, Grid, SceneSpec, find_grid, load_grid,  # isort: skip
                                     parse_grid, shipped_grids)
from gsbench.grids.liveness import (CELL_FILE, CELL_STATUS_FILE, HEARTBEAT_S, STALE_AFTER_S, cell_state,  # isort: skip
                                    pid_alive, read_cell_status, results_finished)
from gsbench.grids.planning import (CACHE_DIRNAME, SCENES_DIRNAME, PlannedCell, cell_config, plan,  # isort: skip
                                    resolve_scene, write_manifest)
from gsbench.grids.priors_share import autoencoder_request, prepare_priors_job, priors_request, shared_priors
from gsbench.grids.running import GridReport, classify, run_cell, run_grid, run_grids
from gsbench.grids.status import format_status, planned_rows, status_rows
from gsbench.store import read_json

__all__ = ["write_failed_results", "CELL_FILE", "CELL_STATUS_FILE", "HEARTBEAT_S",
           "STALE_AFTER_S", "cell_state", "pid_alive", "read_cell_status", "results_finished", "CACHE_DIRNAME",
           "SCENES_DIRNAME", "PlannedCell", "cell_config", "plan", "resolve_scene", "write_manifest",
           "prepare_priors_job", "priors_request", "autoencoder_request", "shared_priors", "GridReport", "classify",
           "run_cell", "run_grids",
           "run_grid", "GRID_DIR", "STUDIES", "Cell", "Grid", "SceneSpec", "find_grid", "load_grid",
           "parse_grid", "shipped_grids", "format_status", "planned_rows", "status_rows", "read_json"]
