"""Published cells written before a method moved config keys, rewritten in today's layout.

A key move (MethodSpec.moved, e.g. d and the autoencoder from `gaussiands` into the shared `semantic`
section) changes no number a cell computes, but it changes the run id, which hashes the config's
layout: every published cell would read stale. `gsbench publish --upgrade STORE` rewrites such a
cell under the run id today's plan gives it, and only when the cell's upgraded config equals the
plan's resolved config for the same cell (method, seed, scene, axes): then today's code computes what
the record holds, which `gsbench verify` re-checks. The record keeps its provenance (the commit that
computed it) and says where it came from (`provenance.upgraded`). All or nothing, like publish.

The same command rewrites a cell written in an older store format (store_format.STORE_VERSION), under
the same run id and with the same content: only the file layout changes.
"""
from __future__ import annotations

import copy
import datetime as _dt
import json
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from gsbench.collect import upgraded_results
from gsbench.config import canonical, upgrade_config, upgrade_key
from gsbench.datasets import load_scene, scene_fingerprint
from gsbench.environment import git_state
from gsbench.errors import InputError, shorten
from gsbench.grids.grid_file import Grid
from gsbench.grids.planning import PlannedCell, plan
from gsbench.grids.store import Published, first_difference, read_store_to_write
from gsbench.grids.store_format import STORE_VERSION, record_text
from gsbench.grids.store_write import StoreWriter
from gsbench.methods.registry import resolve_for_scene


@dataclass
class UpgradeReport:
    upgraded: list[tuple[str, str, str]] = field(default_factory=list)   # (grid, old run id, new run id)
    current: int = 0                                                     # already in today's layout
    reformatted: list[str] = field(default_factory=list)                 # cell files rewritten in today's format
    refused: list[tuple[str, str]] = field(default_factory=list)         # (cell file, why)


def _same(a: object, b: object) -> bool:
    return json.dumps(a, sort_keys=True, default=str) == json.dumps(b, sort_keys=True, default=str)


def _match(cell: dict, planned: list[PlannedCell]) -> list[PlannedCell]:
    """The plan's cells with the record's method, seed, scene and axes (axis keys in today's layout)."""
    axes = {upgrade_key(str(k)): v for k, v in (cell.get("axes") or {}).items()}
    return [pc for pc in planned if pc.cell.method == cell.get("method") and pc.cell.seed == cell.get("seed")
            and _same(pc.cell.scene.to_dict(), cell.get("scene")) and _same(pc.cell.axes, axes)]


def _upgraded_record(c: Published, pc: PlannedCell, scenes: dict, sha: str) -> tuple[dict | None, str]:
    """The record under `pc`'s run id, or (None, why not)."""
    rec = c.record
    sp = str(pc.scene_path)
    if sp not in scenes:
        scenes[sp] = (load_scene(sp), scene_fingerprint(sp))
    scene, fp = scenes[sp]
    if fp != rec["scene_fingerprint"]:
        return None, f"its scene's fingerprint {rec['scene_fingerprint']} is not today's {fp} (a numerics change)"
    results = upgraded_results({**rec["results"], "config": rec["config"]})   # its config and grid axis keys
    config = results.pop("config")
    planned, now = canonical(resolve_for_scene(pc.config, scene)[0]), canonical(config)
    if not _same(planned, now):
        return None, f"its config, upgraded, is not the plan's ({first_difference(planned, now)})"
    new = copy.deepcopy({**rec, "results": results})
    new["run_id"] = pc.run_id
    new["config"] = {**config, "run_id": pc.run_id}
    new["results"]["run_id"] = pc.run_id
    if new["train_summary"].get("run_id") is not None:
        new["train_summary"]["run_id"] = pc.run_id
    new["cell"]["axes"] = dict(pc.cell.axes)
    new["provenance"]["upgraded"] = {
        "from_run_id": c.run_id, "by_commit": sha,
        "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "why": "config keys moved (MethodSpec.moved); the upgraded config is the plan's resolved config"}
    return json.loads(record_text(new)), ""


def _plan_upgrades(cells: list[Published], grids: list[Grid], report: UpgradeReport, sha: str
                   ) -> list[tuple[Published, dict]]:
    """(cell, its record to write) of every cell to rewrite; refusals go to the report. The scenes of
    the plan are generated in a temporary folder to check fingerprints and resolve configs."""
    by_name = {g.name: g for g in grids}
    todo: list[tuple[Published, dict]] = []
    with tempfile.TemporaryDirectory(prefix="gsbench-upgrade-") as tmp:
        plans: dict[str, list[PlannedCell]] = {}
        scenes: dict = {}
        for c in cells:
            if upgrade_config(c.record["config"]) is c.record["config"]:
                report.current += 1
                if c.record.get("store_version") != STORE_VERSION:
                    todo.append((c, c.record))
                continue
            g = by_name.get(c.grid)
            if g is None:
                report.refused.append((str(c.path), f"grid {c.grid} is not in the plan"))
                continue
            if g.name not in plans:
                plans[g.name] = [pc for pc in plan(g, Path(tmp)) if pc.run_id is not None]
            found = _match(c.record["cell"], plans[g.name])
            if len(found) != 1:
                report.refused.append((str(c.path), f"{len(found)} cells of today's plan have its method, seed, "
                                                    "scene and axes (one expected)"))
                continue
            new, why = _upgraded_record(c, found[0], scenes, sha)
            if new is None:
                report.refused.append((str(c.path), why))
            else:
                todo.append((c, new))
    return todo


def upgrade_store(store: Path, grids: list[Grid]) -> UpgradeReport:
    """Rewrite every published cell whose config is in an older layout, or that an older store format
    wrote (module docstring): under the store's writer lock, every cell read first, all of it in one
    step or nothing (gsbench.grids.store_write)."""
    store = Path(store)
    if not store.is_dir():
        raise InputError(f"{shorten(store)}: results store not found (a folder of <grid>/<run_id>.json files)")
    report = UpgradeReport()
    head, dirty = git_state()
    sha = f"{head}{' (uncommitted changes)' if dirty else ''}" if head else "unknown"
    with StoreWriter(store, "gsbench publish --upgrade") as writer:
        cells = list(read_store_to_write(store).values())
        todo = _plan_upgrades(cells, grids, report, sha)
        if report.refused:
            return report
        removes = []
        for c, new in todo:
            if new is c.record:
                report.reformatted.append(str(c.path))
                continue
            if new["run_id"] != c.run_id:
                removes.append((c.grid, c.run_id))
            report.upgraded.append((c.grid, c.run_id, new["run_id"]))
        if todo:
            writer.commit([new for _, new in todo], removes)
    return report


__all__ = ["UpgradeReport", "upgrade_store"]
