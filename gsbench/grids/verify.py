"""`gsbench verify`: re-run published cells from their published configs and compare every metric.

Why: a published number is only worth what a re-run gives. K cells are drawn at random (seeded, so
a failure can be repeated) among the store's cells of today's numerics version; each is trained and
evaluated again by the grid machinery (run_cell) in a temporary folder, on its scene generated
again from the recorded spec (its fingerprint must match), with the published resolved config.

On the CPU family that published the cell (same model name and feature flags) the comparison is
exact: CPU training gives the same bits for any thread count. On another CPU one ulp in the first
steps grows over hundreds of steps into a difference the size of a seed's, so each metric is judged
against the published seeds of the same setting instead (gsbench.grids.seed_spread): within their
prediction interval, or outside it; only "outside" fails. Evaluation's timing metrics are never
compared.
"""
from __future__ import annotations

import copy
import os
import random
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Sequence

from gsbench import rundir
from gsbench.datasets import load_scene, scene_fingerprint
from gsbench.environment import cpu_facts
from gsbench.errors import InputError
from gsbench.grids.grid_file import SceneSpec
from gsbench.grids.planning import resolve_scene
from gsbench.grids.running import run_cell
from gsbench.grids.seed_spread import ALPHA, SpreadRow, judge_all, setting_key
from gsbench.grids.store import TIMING_METRICS, MetricRow, Published, compare_metrics
from gsbench.numerics import NUMERICS_VERSION
from gsbench.store import read_json


def same_cpu(prov: dict, here: dict) -> bool:
    """The published cell ran on this machine's CPU family: same model name and feature flags."""
    return (prov.get("cpu_model") is not None and prov.get("cpu_flags") is not None
            and prov.get("cpu_model") == here.get("cpu_model") and prov.get("cpu_flags") == here.get("cpu_flags"))


@dataclass
class CellCheck:
    cell: Published
    exact: bool
    rows: list[MetricRow | SpreadRow] = field(default_factory=list)
    error: str = ""

    @property
    def ok(self) -> bool:
        return not self.error and all(r.ok for r in self.rows)

    def mode(self) -> str:
        prov = self.cell.record["provenance"]
        if self.exact:
            threads = published_threads(self.cell.record)
            at = f", {threads} torch thread{'s' if threads != 1 else ''} as published" if threads else ""
            return f"exact (same CPU family: {prov.get('cpu_model')}{at})"
        return (f"judged by the seed spread: {100 * (1 - ALPHA):g} % prediction interval of the setting's published "
                f"seeds (published on {prov.get('cpu_model') or 'an unrecorded CPU'}, "
                f"this machine {cpu_facts().get('cpu_model') or 'unknown'})")


def draw(cells: list[Published], k: int, seed: int, grids: Sequence[str] = ()) -> list[Published]:
    """K cells of today's numerics version, drawn at random with `seed` (all of them when fewer). With
    `grids`, only from those grids and spread over them in turn (the i-th cell from grid i mod n), so
    K = n checks one cell of each named grid, e.g. one grid per regime."""
    pool = sorted((c for c in cells if c.numerics_version == NUMERICS_VERSION), key=lambda c: (c.grid, c.run_id))
    rng = random.Random(seed)
    if not grids:
        return rng.sample(pool, min(max(k, 0), len(pool)))
    unknown = sorted(set(grids) - {c.grid for c in pool})
    if unknown:
        raise InputError(f"--grids: no published cell of numerics version {NUMERICS_VERSION} in "
                         f"{', '.join(unknown)} (grids in the store: {', '.join(sorted({c.grid for c in pool}))})")
    queues = []
    for g in dict.fromkeys(grids):
        cells_g = [c for c in pool if c.grid == g]
        queues.append(rng.sample(cells_g, len(cells_g)))
    out: list[Published] = []
    while len(out) < max(k, 0) and any(queues):
        for q in queues:
            if q and len(out) < k:
                out.append(q.pop(0))
    return out


def _rerun(cell: Published, work: Path) -> dict[str, Any]:
    """Train and evaluate the cell again under work/; its results.json."""
    rec = cell.record
    try:
        scene = SceneSpec(**rec["cell"]["scene"])
    except (KeyError, TypeError):
        raise InputError(f"{cell.path}: cell.scene is not a scene spec "
                         "(preset or path, seed, views, resolution)") from None
    scene_path = resolve_scene(scene, work)
    fp = scene_fingerprint(scene_path)
    if fp != rec["scene_fingerprint"]:
        raise RuntimeError(f"scene {scene.label} generated again has fingerprint {fp[:12]}, the cell's is "
                           f"{str(rec['scene_fingerprint'])[:12]}")
    _check_points(scene_path, rec, cell)
    config = copy.deepcopy(rec["config"])
    if isinstance(config.get("priors"), dict):
        config["priors"]["cache_dir"] = str((work / rundir.CACHE_DIRNAME).resolve())
    run_dir = work / cell.run_id
    spec = {"run_dir": str(run_dir), "scene_path": str(scene_path), "config": config, "study": rec.get("study"),
            "axes": rec["cell"].get("axes", {}), "scene": scene.to_dict(), "seed": rec["cell"].get("seed"),
            "method": rec["cell"].get("method")}
    with thread_budget(published_threads(rec)):
        out = run_cell(spec)
    if out["state"] != "done":
        raise RuntimeError(f"the re-run {out['state']}: {out.get('error')}")
    return read_json(run_dir / rundir.RESULTS)


def _check_points(scene_path: Path, rec: dict, cell: Published) -> None:
    """A capture's sparse points come from `gsbench points`: a re-run on other points is another
    initialisation, so it is refused with both digests. Cells written before the digest was recorded
    carry none, and the re-run is not checked (the report's numbers then judge it)."""
    want = ((rec.get("config") or {}).get("scene") or {}).get("points")
    if not isinstance(want, str):
        return
    have = load_scene(scene_path).points_digest()
    if have != want:
        raise RuntimeError(f"{cell.path}: the scene at {scene_path} has sparse points {have or 'none'}, the cell "
                           f"was trained from points {want}; for a capture, `gsbench points {scene_path} --force "
                           f"--seed 0` writes the points one seed gives on this machine")


def published_threads(rec: dict) -> int | None:
    """The torch thread count the cell was trained and evaluated with (its provenance), None when it
    recorded none. Some reductions outside the training step (the autoencoder, the priors' products,
    the evaluation) split their work by it, so a re-run on the same CPU family matches bit for bit only
    at the same count."""
    n = (rec.get("provenance") or {}).get("torch_threads")
    return n if isinstance(n, int) and not isinstance(n, bool) and n >= 1 else None


@contextmanager
def thread_budget(threads: int | None) -> Iterator[None]:
    """Run the block with GSBENCH_THREADS / OMP / MKL set to `threads` (as a grid worker does), then put
    the environment and torch's thread count back; None changes nothing."""
    if threads is None:
        yield
        return
    import torch  # lazy: gsbench verify's start-up does not need it before a cell runs
    keys = ("GSBENCH_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    before, torch_before = {k: os.environ.get(k) for k in keys}, torch.get_num_threads()
    os.environ.update({k: str(threads) for k in keys})
    torch.set_num_threads(threads)
    try:
        yield
    finally:
        for k, v in before.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        torch.set_num_threads(torch_before)


def same_setting(cell: Published, cells: list[Published]) -> list[dict]:
    """The records of the published seeds of `cell`'s setting (its own included), of today's numerics."""
    key = setting_key(cell.record)
    return [c.record for c in cells if c.numerics_version == NUMERICS_VERSION and setting_key(c.record) == key]


def compare_rerun(cell: Published, now: dict, exact: bool, cells: list[Published]) -> list[MetricRow | SpreadRow]:
    """The re-run's metrics against the cell's: equal bits on the CPU family that published it, else
    each within the prediction interval of its setting's published seeds (module docstring)."""
    if exact:
        return compare_metrics(cell.metrics, now)
    return judge_all(cell.metrics, now, same_setting(cell, cells), TIMING_METRICS)


def verify_cell(cell: Published, work: Path, cells: list[Published]) -> CellCheck:
    """Re-run one cell under work/ and compare its metrics with the published ones (`cells`: the
    store, whose seeds of the same setting judge a re-run on another CPU)."""
    check = CellCheck(cell, same_cpu(cell.record["provenance"], cpu_facts()))
    try:
        now = _rerun(cell, work)
    except (RuntimeError, InputError) as e:
        check.error = str(e)
        return check
    check.rows = compare_rerun(cell, now.get("metrics") or {}, check.exact, cells)
    return check


def verify(cells: list[Published], k: int, seed: int, grids: Sequence[str] = ()) -> list[CellCheck]:
    """Draw K cells (from `grids` in turn, when named) and check each in its own temporary folder."""
    out = []
    for cell in draw(cells, k, seed, grids):
        with tempfile.TemporaryDirectory(prefix="gsbench-verify-") as tmp:
            out.append(verify_cell(cell, Path(tmp), cells))
    return out


def format_check(check: CellCheck) -> str:
    """The cell's comparison as a per-metric table (metrics null on both sides are left out)."""
    c = check.cell
    head = f"cell {c.grid}/{c.run_id} ({c.record['cell'].get('method')}, seed {c.record['cell'].get('seed')}): "
    if check.error:
        return head + f"MISMATCH: {check.error}"
    lines = [head + check.mode()]
    shown = [r for r in check.rows if r.published is not None or r.now is not None]
    width = max([len("metric")] + [len(r.metric) for r in shown])
    spread = not check.exact
    lines.append(f"  {'metric':{width}s}  {'published':>22s}  {'now':>22s}  "
                 + (f"{'seed interval (n)':>30s}  " if spread else "") + "result")
    for r in shown:
        lines.append(f"  {r.metric:{width}s}  {_num(r.published):>22s}  {_num(r.now):>22s}  "
                     + (f"{_interval(r):>30s}  {r.verdict}" + (" (one ulp can flip it)" if r.flip_prone else "")
                        if spread else ("ok" if r.ok else "MISMATCH")))
    bad = sum(not r.ok for r in check.rows)
    word = "outside the seed spread" if spread else "mismatched"
    lines.append(f"  {len(check.rows)} metrics compared ({len(shown)} with a value), {bad} {word}")
    return "\n".join(lines)


def _interval(r: SpreadRow) -> str:
    if r.interval is None:
        return f"none ({r.n})"
    return f"[{r.interval[0]:.6g}, {r.interval[1]:.6g}] ({r.n})"


def _num(v: Any) -> str:
    return "null" if v is None else repr(v)
