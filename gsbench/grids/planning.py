"""Planning: scene folders of a grid (generated once), each cell's resolved config and run id,
and the grid manifest that `ablate --status` and `gsbench collect` read."""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

from gsbench import rundir
from gsbench.config import get_dotted, load_config
from gsbench.config import run_id as make_run_id
from gsbench.datasets import load_scene, scene_fingerprint
from gsbench.datasets.synthetic import make_scene
from gsbench.errors import InputError
from gsbench.grids.grid_file import Cell, Grid, SceneSpec
from gsbench.priors.depth import asks_depth_rule, settle_depth_rule
from gsbench.store import write_json_atomic

CACHE_DIRNAME = rundir.CACHE_DIRNAME
SCENES_DIRNAME = "scenes"


def scene_folder(spec: SceneSpec) -> tuple[Path, str]:
    """A folder scene's path with `~` and environment variables expanded, and why it cannot be used
    ('' when it is a folder here)."""
    p = Path(os.path.expandvars(os.path.expanduser(spec.path or "")))
    if "$" in str(p):
        return p, f"scene {spec.path!r}: unset environment variable in the path"
    if not p.is_dir():
        return p, f"scene {p}: folder not found"
    return p, ""


def resolve_scene(spec: SceneSpec, runs_dir: Path, create: bool = True) -> Optional[Path]:
    """A scene folder for `spec`: presets are generated once into RUNS_DIR/scenes/<preset>-<seed>
    (into a temp folder renamed into place, so concurrent or killed runs never see half a scene).
    With create=False a missing preset scene gives None."""
    if spec.path:
        p, why = scene_folder(spec)
        if why:
            raise InputError(why)
        return p.resolve()
    out = (runs_dir / SCENES_DIRNAME / spec.folder_name()).resolve()
    if out.is_dir():
        return out
    if not create:
        return None
    tmp = out.parent / f".{out.name}.tmp-{os.getpid()}"
    tmp.parent.mkdir(parents=True, exist_ok=True)
    kwargs: dict[str, Any] = {"seed": spec.seed}
    if spec.views:
        kwargs["views"] = spec.views
    if spec.resolution:
        kwargs["resolution"] = tuple(spec.resolution)
    made = Path(make_scene(spec.preset, tmp, **kwargs))
    if made.resolve() != tmp.resolve():
        raise RuntimeError(f"make_scene wrote {made}, expected {tmp}")
    try:
        os.replace(tmp, out)
    except OSError:
        if not out.is_dir():  # another process won the race: keep theirs
            raise
        import shutil
        shutil.rmtree(tmp, ignore_errors=True)
    return out


# ----------------------------------------------------------------------------- cell configs
def cell_config(cell: Cell, runs_dir: Path, grid_axis_keys: list[str]) -> dict:
    """The resolved config of a cell: default <- preset <- base.set <- axes, plus the shared priors
    cache and the study/grid record (reports read them from results.json)."""
    overrides = dict(cell.overrides)
    overrides["priors.cache_dir"] = str((runs_dir / CACHE_DIRNAME).resolve())
    config = load_config(cell.method, cell.preset, overrides)   # {dotted key: value}, no YAML round trip
    config["study"] = cell.study
    grid_values = {}
    for k in grid_axis_keys:
        try:
            grid_values[k] = get_dotted(config, k)
        except KeyError:
            grid_values[k] = None
    config["grid"] = grid_values
    return config


@dataclass
class PlannedCell:
    cell: Cell
    config: dict
    scene_path: Optional[Path]
    run_id: Optional[str]
    run_dir: Optional[Path]

    def spec(self) -> dict:
        """What a worker needs (plain, picklable)."""
        return {"run_dir": str(self.run_dir), "scene_path": str(self.scene_path), "config": self.config,
                "study": self.cell.study, "axes": self.cell.axes, "scene": self.cell.scene.to_dict(),
                "seed": self.cell.seed, "method": self.cell.method}


def missing_scene_folders(grid: Grid) -> list[str]:
    """Why each folder scene of `grid` is not here (an unset variable in its path, or no such folder);
    [] when every scene can be resolved (presets are generated)."""
    specs = {json.dumps(c.scene.to_dict(), sort_keys=True): c.scene for c in grid.cells()}.values()
    return [why for why in (scene_folder(s)[1] for s in specs if s.path) if why]


@dataclass(frozen=True)
class GeneratedSceneFacts:
    """What the scene-decided rules (`priors.depth.provider: auto`) read of a generated scene without
    generating it: the generator writes GT depth for every view (datasets/synthetic.py)."""
    has_depth: bool = True
    has_points: bool = True


def settle_on_spec(config: dict, spec: SceneSpec) -> dict:
    """`config` settled (`settle_depth_rule`) on the scene `spec` names without generating it: a preset's
    facts from its generator, a folder's from the folder when it is here (else unsettled: its id is then
    the rule's own, which no published cell has)."""
    if not asks_depth_rule(config):
        return config
    if spec.preset:
        return settle_depth_rule(config, GeneratedSceneFacts())
    folder, why = scene_folder(spec)
    return settle_depth_rule(config, load_scene(folder)) if spec.path and not why else config


def plan(grid: Grid, runs_dir: Path, create_scenes: bool = True) -> list[PlannedCell]:
    """Resolve scenes (generating presets once), configs and run ids of every cell."""
    runs_dir = Path(runs_dir)
    scene_paths: dict[str, Optional[Path]] = {}
    fingerprints: dict[str, str] = {}
    loaded: dict[str, Any] = {}
    seen_ids: set[str] = set()
    out = []
    for cell in grid.cells():
        skey = json.dumps(cell.scene.to_dict(), sort_keys=True)
        if skey not in scene_paths:
            scene_paths[skey] = resolve_scene(cell.scene, runs_dir, create=create_scenes)
            if scene_paths[skey] is not None:
                fingerprints[skey] = scene_fingerprint(scene_paths[skey])
        config = cell_config(cell, runs_dir, grid.axis_keys)
        sp = scene_paths[skey]
        if sp is None:
            out.append(PlannedCell(cell, config, None, None, None))
            continue
        if asks_depth_rule(config):   # `auto` is settled on the scene before the id is taken
            if skey not in loaded:
                loaded[skey] = load_scene(sp)
            config = settle_depth_rule(config, loaded[skey])
        rid = make_run_id(config, fingerprints[skey])
        if rid in seen_ids:
            continue   # the same resolved config reached through two sweeps
        seen_ids.add(rid)
        out.append(PlannedCell(cell, config, sp, rid, runs_dir / rid))
    return out


def write_manifest(grid: Grid, runs_dir: Path, planned: list[PlannedCell]) -> Path:
    """RUNS_DIR/grid-<name>.json: which run folders belong to the grid (status and collect use it)."""
    path = runs_dir / f"grid-{grid.name}.json"
    write_json_atomic(path, {
        "grid": grid.name, "study": grid.study, "grid_file": str(grid.path) if grid.path else None,
        "axis_keys": grid.axis_keys,
        "cells": [{"run_id": pc.run_id, "method": pc.cell.method, "scene": pc.cell.scene.label, "seed": pc.cell.seed,
                   "axes": pc.config.get("grid", {})} for pc in planned],
    })
    return path
