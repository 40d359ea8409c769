"""The published results store: one JSON file per finished cell of the claims plan, kept in the
repository (results/cpu), so a run can be spread over sessions and every number can be checked.

    STORE/<grid>/<run_id>.json   {store_version, numerics_version, grid, study, run_id, cell, scene_fingerprint,
                                  config, results, train_summary, provenance}

`config` is the run's resolved config.json (results.json's own copy of it is left out of `results`:
it is the same object), `cell` the grid cell (method, seed, scene spec, axes), `provenance` the
commit, machine, versions, date and wall times. No model file: a cell is about 11 kB (its per-view
values one packed block), and the parts most cells share word for word are kept once under
STORE/_shared (gsbench.grids.store_format).

Why here (floor 3): publishing re-plans the grids (gsbench.grids.planning) and checks each run
folder against its plan; `gsbench claims` materialises published cells back into run folders.
A cell is *current* when its numerics version is the code's (gsbench.numerics) and its run id is
one the plan gives today; else it is *stale* and never reused nor shown in the table. The page
reads only current cells (gsbench.reports.claims_page). docs/publishing.md has the rules.
"""
from __future__ import annotations

import datetime as _dt
import json
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Optional

from gsbench import rundir
from gsbench.collect import number_problem
from gsbench.config import canonical, flatten, short_repr
from gsbench.config import run_id as make_run_id
from gsbench.datasets import load_scene
from gsbench.errors import InputError, shorten
from gsbench.grids.claims_plan import plan_grids, plan_names
from gsbench.grids.grid_file import Grid, SceneSpec, load_grid
from gsbench.grids.liveness import cell_state
from gsbench.grids.planning import PlannedCell, cell_config, plan, settle_on_spec
from gsbench.grids.store_format import (
    STORE_VERSION,
    cell_files,
    check_numbers,
    read_record,
    record_text,
)
from gsbench.grids.store_write import StoreWriter
from gsbench.methods.registry import resolve_for_scene
from gsbench.metric_table import TIMING_NAMES
from gsbench.numerics import NUMERICS_VERSION
from gsbench.runlock import RunLock
from gsbench.store import read_json, write_json_atomic

RECORD_KEYS = ("store_version", "numerics_version", "grid", "study", "run_id", "cell", "scene_fingerprint",
               "config", "results", "train_summary", "provenance")
# evaluation's timing metrics differ from run to run: never compared, never a reason to refuse
TIMING_METRICS = frozenset(("fps",) + TIMING_NAMES)
PUBLISHED_BY = "published"           # cell_status.json key of a materialised cell: the record it came from


def plan_for(names: Optional[Iterable[str]] = None, quick: bool = False) -> list[Grid]:
    """The grids a store is checked against: the claims plan (its --quick variant with `quick`), or
    the named grids of it and grid files (a test's tiny plan)."""
    if not names:
        return plan_grids(quick=quick)
    out = []
    known = plan_names()
    for name in names:
        if name in known:
            out += plan_grids(quick=quick, names=(name,))
        elif Path(name).suffix in (".yaml", ".yml") and Path(name).is_file():
            out.append(load_grid(name))
        else:
            raise InputError(f"--grids {short_repr(name, 60)}: neither a grid of the claims plan "
                             f"({', '.join(known)}) nor a grid file")
    return out


def repo_store() -> Optional[Path]:
    """The repository's results/cpu when gsbench runs from a checkout that has one, else None."""
    p = Path(__file__).resolve().parents[2] / "results" / "cpu"
    return p if p.is_dir() else None


def record_path(store: Path, grid: str, run_id: str) -> Path:
    return Path(store) / grid / f"{run_id}.json"


@dataclass
class Published:
    """One cell of the store as read."""
    path: Path
    record: dict

    @property
    def run_id(self) -> str:
        return str(self.record["run_id"])

    @property
    def grid(self) -> str:
        return str(self.record["grid"])

    @property
    def numerics_version(self) -> Any:
        return self.record.get("numerics_version")

    @property
    def metrics(self) -> dict:
        return self.record["results"].get("metrics") or {}


def _check_record(rec: Any, path: Path) -> None:
    """The shape every reader relies on, as an InputError naming the file."""
    if not isinstance(rec, dict):
        raise InputError(f"{shorten(path)}: a published cell must hold a JSON object")
    missing = [k for k in RECORD_KEYS if k not in rec]
    if missing:
        raise InputError(f"{shorten(path)}: not a published cell (missing {', '.join(missing)})")
    for k in ("cell", "config", "results", "train_summary", "provenance"):
        if not isinstance(rec[k], dict):
            raise InputError(f"{shorten(path)}: '{k}' must be an object")
    if path.stem != rec["run_id"] or path.parent.name != rec["grid"]:
        raise InputError(f"{shorten(path)}: holds cell {short_repr(rec['run_id'])} of grid {short_repr(rec['grid'])}; "
                         "a cell's file is STORE/<grid>/<run_id>.json")


def read_store(store: Path) -> list[Published]:
    """Every cell of the store, sorted by grid and run id; an empty store gives []."""
    store = Path(store)
    if not store.is_dir():
        raise InputError(f"{shorten(store)}: results store not found (a folder of <grid>/<run_id>.json files)")
    out = []
    for p in cell_files(store):
        rec = read_record(p)
        _check_record(rec, p)
        out.append(Published(p, rec))
    return out


# ----------------------------------------------------------------------------- current or stale
@dataclass
class Stale:
    cell: Published
    reason: str


def _scene_key(scene: Any) -> str:
    return json.dumps(scene, sort_keys=True, default=str)


def store_backend(cells: list[Published], where: Path) -> str:
    """The one backend (`config.backend`) that produced a store's cells; an error naming the store when
    its cells disagree or none records one (a store holds one backend's cells)."""
    found = {(c.record.get("config") or {}).get("backend") for c in cells}
    if len(found) != 1 or None in found:
        raise InputError(f"{shorten(where)}: expected the cells of one backend, found "
                         f"{', '.join(sorted(str(b) for b in found)) or 'no cell'}")
    return str(found.pop())


def plan_on_backend(grids: list[Grid], backend: str) -> list[Grid]:
    """The plan's grids with `backend` added to each base.set, as scripts/gpu_claims.py runs them on a
    GPU: another backend's cells have their own run ids, so its store is classified against this plan."""
    return [replace(g, base_set={**g.base_set, "backend": backend}) for g in grids]


def plan_of_store(grids: list[Grid], cells: list[Published], where: Path) -> list[Grid]:
    """The plan a store is checked against: `grids` as they are when the store holds the backend they
    resolve to (or nothing), else the plan on the store's one backend (`plan_on_backend`)."""
    if not cells:
        return grids
    backend = store_backend(cells, where)
    planned = {g.base_tree().get("backend") for g in grids}
    return grids if planned == {backend} else plan_on_backend(grids, backend)


def classify(cells: list[Published], grids: list[Grid]) -> tuple[list[Published], list[Stale]]:
    """(current, stale) cells against the plan of `grids` and today's numerics version.

    The plan's run ids are computed from today's configs and each cell's recorded scene
    fingerprint, so no scene is generated (a scene generator change is a numerics change)."""
    by_name = {g.name: g for g in grids}
    configs: dict[str, list[tuple[str, dict]]] = {}     # grid -> (scene key, config) per cell, when first needed
    ids: dict[tuple[str, str, str], set[str]] = {}
    current, stale = [], []
    for c in cells:
        if c.numerics_version != NUMERICS_VERSION:
            stale.append(Stale(c, f"numerics version {c.numerics_version}, the code's is {NUMERICS_VERSION}"))
            continue
        g = by_name.get(c.grid)
        if g is None:
            stale.append(Stale(c, f"grid {c.grid} is not in the plan"))
            continue
        if g.name not in configs:
            configs[g.name] = [(_scene_key(x.scene.to_dict()), cell_config(x, Path("."), g.axis_keys))
                               for x in g.cells()]
        skey, fp = _scene_key(c.record["cell"].get("scene")), str(c.record["scene_fingerprint"])
        key = (c.grid, skey, fp)
        if key not in ids:
            try:
                spec: SceneSpec | None = SceneSpec(**c.record["cell"]["scene"])
            except TypeError:   # not a scene spec: no config of today's plan settles on it
                spec = None
            ids[key] = {make_run_id(settle_on_spec(cfg, spec) if spec else cfg, fp)
                        for k, cfg in configs[g.name] if k == skey}
        if c.run_id in ids[key]:
            current.append(c)
        else:
            stale.append(Stale(c, "not a cell of today's plan (its config, a default or its scene changed)"))
    return current, stale


def format_store_status(cells: list[Published], current: list[Published], stale: list[Stale],
                        grids: list[Grid]) -> str:
    """Counts per grid (published current / cells of the plan) and every stale cell with its reason."""
    lines = [f"{'grid':28s} {'current':>7s} {'of plan':>7s} {'stale':>5s}"]
    for g in grids:
        n_cur = sum(c.grid == g.name for c in current)
        n_stale = sum(s.cell.grid == g.name for s in stale)
        lines.append(f"{g.name:28s} {n_cur:7d} {len(g.cells()):7d} {n_stale:5d}")
    for s in stale:
        lines.append(f"stale: {s.cell.grid}/{s.cell.run_id}: {s.reason}")
    lines.append(f"{len(cells)} published cells: {len(current)} current, {len(stale)} stale "
                 f"(numerics version {NUMERICS_VERSION})")
    return "\n".join(lines)


# ----------------------------------------------------------------------------- comparing numbers
@dataclass
class MetricRow:
    metric: str
    published: Any
    now: Any
    ok: bool


def compare_metrics(published: dict, now: dict, rtol: float = 0.0, atol: float = 0.0) -> list[MetricRow]:
    """Every metric of either side but the timing ones: equal (both null), or both numbers within
    atol + rtol * |published| (exact with the defaults)."""
    rows = []
    for m in sorted(set(published) | set(now)):
        if m in TIMING_METRICS:
            continue
        a, b = published.get(m), now.get(m)
        if number_problem(a) or number_problem(b):
            ok = False                          # not a number: never equal (readers refuse it first)
        elif a is None or b is None:
            ok = a is None and b is None
        else:
            fa, fb = float(a), float(b)
            ok = fa == fb or (math.isfinite(fa) and math.isfinite(fb) and abs(fa - fb) <= atol + rtol * abs(fa))
        rows.append(MetricRow(m, a, b, ok))
    return rows


# ----------------------------------------------------------------------------- publishing
@dataclass
class PublishReport:
    written: list[Path] = field(default_factory=list)
    unchanged: list[str] = field(default_factory=list)
    replaced: list[str] = field(default_factory=list)
    refused: list[tuple[str, str]] = field(default_factory=list)    # (run folder, why)
    not_finished: int = 0


def provenance(env: dict, summary: dict, results: dict, finished: Optional[float]) -> dict:
    """Who and what computed a cell: commit, machine, versions, date and wall times."""
    date = (_dt.datetime.fromtimestamp(finished, _dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
            if isinstance(finished, (int, float)) and math.isfinite(finished) else None)
    return {"gsbench_commit": env.get("git_sha"), "gsbench_commit_dirty": env.get("git_dirty"),
            "gsbench_version": env.get("gsbench"),
            "numerics_version": env.get("numerics_version"), "cpu_model": env.get("cpu_model"),
            "cpu_flags": env.get("cpu_flags"), "physical_cores": env.get("physical_cores"),
            "logical_cpus": env.get("cores"), "torch_threads": env.get("torch_threads"), "host": env.get("host"),
            "torch": env.get("torch"), "numba": env.get("numba"), "numpy": env.get("numpy"),
            "python": env.get("python"), "platform": env.get("platform"),
            "numba_threading_layer": summary.get("numba_threading_layer"), "date": date,
            "train_s": summary.get("train_s"), "eval_s": (results.get("timings") or {}).get("eval_s")}


def _json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, default=str)


def first_difference(a: dict, b: dict) -> str:
    """The first dotted key where `b` (the run's) differs from `a` (the plan's), with both values."""
    fa, fb = flatten(a), flatten(b)
    for k in sorted(set(fa) | set(fb)):
        if _json(fa.get(k)) != _json(fb.get(k)):
            return f"{k}: {short_repr(fb.get(k), 40)}, the plan's {short_repr(fa.get(k), 40)}"
    return "?"


def _numerics_problem(env: dict, results: dict) -> Optional[str]:
    trained, evaluated = env.get("numerics_version"), (results.get("machine") or {}).get("numerics_version")
    if trained is None or evaluated is None:
        return "no numerics version recorded (trained or evaluated before gsbench recorded one); re-run it"
    if trained != NUMERICS_VERSION or evaluated != NUMERICS_VERSION:
        return (f"trained at numerics version {trained}, evaluated at {evaluated}; the code's is "
                f"{NUMERICS_VERSION}: re-run it")
    return None


def _cell_record(g: Grid, pc: PlannedCell, results: dict, scenes: dict) -> tuple[Optional[dict], str]:
    """The record of one finished cell of the plan, or (None, why it is refused)."""
    run_dir = Path(pc.run_dir)
    config = read_json(run_dir / rundir.CONFIG) if (run_dir / rundir.CONFIG).exists() else None
    summary = rundir.read_optional(run_dir / rundir.TRAIN_SUMMARY)
    env = rundir.read_optional(run_dir / rundir.ENV)
    if not isinstance(config, dict) or not isinstance(summary, dict) or summary.get("status") != "done":
        return None, "config.json or a finished train_summary.json is missing"
    for name, rid in (("results.json", results.get("run_id")), ("config.json", config.get("run_id"))):
        if rid != pc.run_id:
            return None, f"{name} names run {short_repr(rid, 40)}, the plan's cell is {pc.run_id}"
    if results.get("config") != config:
        return None, "results.json's config differs from config.json (the folder mixes two runs)"
    why = _numerics_problem(env if isinstance(env, dict) else {}, results)
    if why:
        return None, why
    sp = str(pc.scene_path)
    if sp not in scenes:
        scenes[sp] = load_scene(sp)
    planned = canonical(resolve_for_scene(pc.config, scenes[sp])[0])
    if _json(planned) != _json(canonical(config)):
        return None, f"config.json is not the plan's config ({first_difference(planned, canonical(config))})"
    cell_st = rundir.read_optional(run_dir / rundir.CELL_STATUS)
    finished = cell_st.get("finished") or (rundir.read_status(run_dir) or {}).get("time")
    rec = {"store_version": STORE_VERSION, "numerics_version": NUMERICS_VERSION, "grid": g.name, "study": g.study,
           "run_id": pc.run_id, "scene_fingerprint": (config.get("scene") or {}).get("fingerprint"),
           "cell": {"method": pc.cell.method, "seed": pc.cell.seed, "scene": pc.cell.scene.to_dict(),
                    "axes": pc.cell.axes},
           "config": config, "results": {k: v for k, v in results.items() if k != "config"},
           "train_summary": summary, "provenance": provenance(env, summary, results, finished)}
    return json.loads(record_text(rec)), ""


def _unplanned_runs(runs_dir: Path, grids: list[Grid], planned: set[str]) -> list[tuple[str, str]]:
    """Finished runs of the plan's studies in RUNS that are no cell of today's plan (another config
    or older defaults): refused, so they cannot be mistaken for the plan's."""
    studies = {g.study for g in grids}
    out = []
    for p in sorted(Path(runs_dir).glob(f"*/{rundir.RESULTS}")):
        rid = p.parent.name
        if rid in planned or rid.startswith("."):
            continue
        try:
            res = read_json(p)
        except InputError:
            continue
        if isinstance(res, dict) and res.get("study") in studies and res.get("status") == "done":
            out.append((str(p.parent), f"a finished run of study {res.get('study')} that is no cell of today's "
                                       "plan (trained with another config or older defaults)"))
    return out


def _collect_records(runs_dir: Path, grids: list[Grid], report: PublishReport) -> list[dict]:
    """The records of every finished cell of the plan in RUNS; refusals go to the report."""
    scenes: dict = {}
    planned_ids: set[str] = set()
    records = []
    for g in grids:
        for pc in plan(g, runs_dir, create_scenes=False):
            if pc.run_id is None:
                continue
            planned_ids.add(pc.run_id)
            res_path = Path(pc.run_dir) / rundir.RESULTS
            if not res_path.exists():
                continue
            results = read_json(res_path)
            if not isinstance(results, dict) or results.get("status") != "done" or cell_state(pc.run_dir) != "done":
                report.not_finished += 1
                continue
            rec, why = _cell_record(g, pc, results, scenes)
            try:
                if rec is not None:
                    check_numbers(rec, res_path)
            except InputError as e:
                rec, why = None, str(e)
            if rec is None:
                report.refused.append((str(pc.run_dir), why))
            else:
                records.append(rec)
    report.refused += _unplanned_runs(runs_dir, grids, planned_ids)
    return records


def read_store_to_write(store: Path) -> dict[Path, Published]:
    """Every cell of a store about to be written, read whole (parts, numbers) under its writer lock: a
    corrupt cell, even one the write does not touch, stops the write before anything is written."""
    if not Path(store).exists():
        return {}
    try:
        return {c.path: c for c in read_store(store)}
    except InputError as e:
        raise InputError(f"{e}; nothing was written") from None


def _compare_with_store(records: list[dict], store: Path, old_cells: dict[Path, Published],
                        runs_dir: Path, report: PublishReport) -> list[dict]:
    """The records to write: new cells, and cells of an older numerics version (replaced); a cell
    published with other numbers at today's numerics version is refused."""
    todo = []
    for rec in records:
        path = record_path(store, rec["grid"], rec["run_id"])
        found = old_cells.get(path)
        old = found.record if found is not None else None
        if old is not None and old.get("numerics_version") == NUMERICS_VERSION:
            bad = [r.metric for r in compare_metrics((old.get("results") or {}).get("metrics") or {},
                                                     rec["results"].get("metrics") or {}) if not r.ok]
            if bad:
                report.refused.append((str(runs_dir / rec["run_id"]),
                                       f"published before with other numbers ({', '.join(bad[:4])}) at the same "
                                       "numerics version: a change that moves numbers needs a NUMERICS_VERSION bump"))
            else:
                report.unchanged.append(rec["run_id"])
            continue
        (report.replaced if old is not None else report.written).append(path)
        todo.append(rec)
    return todo


def publish(runs_dir: Path, store: Path, grids: list[Grid]) -> PublishReport:
    """Add every finished cell of the plan in RUNS to the store. All or nothing: when any cell is
    refused (not the plan's config, another numerics version, other numbers than the published
    cell of the same run id), or any cell of the store cannot be read, nothing is written; else the
    new cells, their parts and the prune change the store in one step (gsbench.grids.store_write),
    under the store's writer lock."""
    runs_dir, store = Path(runs_dir), Path(store)
    if not runs_dir.is_dir():
        raise InputError(f"{shorten(runs_dir)}: runs folder not found")
    report = PublishReport()
    records = _collect_records(runs_dir, grids, report)
    if not records and not report.refused:
        raise InputError(f"{shorten(runs_dir)}: no finished cell of the plan ({report.not_finished} unfinished); is "
                         "it a `gsbench claims --out` folder? (--quick or --grids choose another plan)")
    with StoreWriter(store, "gsbench publish") as writer:
        todo = _compare_with_store(records, store, read_store_to_write(store), runs_dir, report)
        if report.refused:
            report.written, report.replaced = [], []
            return report
        if todo:
            writer.commit(todo)
    return report


# ----------------------------------------------------------------------------- reuse by `gsbench claims`
def materialise(rec: dict, run_dir: Path, spec: dict, source: Path) -> None:
    """A published cell as a finished run folder that collect, the report and the grid status read
    (results.json, config.json, train_summary.json, env.json, status.json, cell.json and, last,
    cell_status.json saying done); no model, so nothing can retrain or re-evaluate it by accident."""
    run_dir = Path(run_dir)
    env = {k: rec["provenance"].get(v) for k, v in (("git_sha", "gsbench_commit"), ("gsbench", "gsbench_version"),
                                                    ("platform", "platform"), ("cpu_model", "cpu_model"),
                                                    ("numerics_version", "numerics_version"))}
    with RunLock(run_dir, command=f"gsbench claims: published cell {rec['run_id']}"):
        write_json_atomic(run_dir / rundir.CONFIG, rec["config"])
        write_json_atomic(run_dir / rundir.ENV, env)
        write_json_atomic(run_dir / rundir.TRAIN_SUMMARY, rec["train_summary"])
        write_json_atomic(run_dir / rundir.RESULTS, {**rec["results"], "config": rec["config"]})
        write_json_atomic(run_dir / rundir.CELL, {k: v for k, v in spec.items() if k != "config"})
        rundir.write_status(run_dir, "done", f"published cell {source}")
        write_json_atomic(run_dir / rundir.CELL_STATUS, {"state": "done", "phase": "done", "attempt": 0,
                                                         "finished": time.time(), "wall_s": 0.0,
                                                         PUBLISHED_BY: str(source)})


def reuse_published(grid: Grid, runs_dir: Path, store: Path, log: Callable[[str], None]) -> int:
    """Materialise every published cell of `grid` whose run id (today's plan, scenes generated in
    RUNS) and numerics version match into RUNS/<run_id>, so run_grid counts it done and never trains
    it. A run folder already there is left alone (done, or a run of this cell in progress)."""
    runs_dir, store = Path(runs_dir), Path(store)
    if not store.is_dir():
        raise InputError(f"{shorten(store)}: results store not found (a folder of <grid>/<run_id>.json files)")
    if not (store / grid.name).is_dir():
        return 0
    reused, kept = 0, 0
    for pc in plan(grid, runs_dir):
        if pc.run_id is None or not record_path(store, grid.name, pc.run_id).exists():
            continue
        path = record_path(store, grid.name, pc.run_id)
        rec = read_record(path)
        _check_record(rec, path)
        if rec["numerics_version"] != NUMERICS_VERSION:
            continue
        run_dir = Path(pc.run_dir)
        if run_dir.exists() and any(run_dir.iterdir()):
            kept += cell_state(run_dir) != "done"
            continue
        materialise(rec, run_dir, pc.spec(), path)
        reused += 1
    if reused or kept:
        log(f"grid {grid.name}: {reused} published cells reused from {store}"
            + (f"; {kept} with a local run folder in progress kept (not replaced)" if kept else ""))
    return reused
