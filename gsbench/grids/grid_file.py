"""Grid files: parse and validate a grid YAML into a Grid, and expand it into cells.

A grid file names a base config, scenes, seeds and axes (the format is in docs/grids.md).
Every value (base.set, axes, sweeps, extra cells, `ablate --set`) goes through
gsbench.config.check_value, the one checker of config keys, types and ranges.
"""
from __future__ import annotations

import itertools
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

from gsbench.config import (
    check_value,
    default_tree,
    flatten,
    load_tree,
    load_yaml_file,
    parse_overrides,
    preset_path,
    short_repr,
)
from gsbench.datasets import synthetic
from gsbench.errors import InputError
from gsbench.methods.gaussiands import study_table

GRID_DIR = Path(__file__).parent

# Study names and the axis keys they vary: the one studies table, methods/gaussiands/study_table.py.
# A grid of a paper study may vary only that study's axes; a control or smoke study (e.g. tiny-test)
# is a name, not a contract, so its grids may vary anything.


def study_axes() -> dict[str, tuple[str, ...]]:
    """The paper studies' axes, read from the study table when called (a study declared later included)."""
    return {name: st.axes for name, st in study_table.studies().items() if st.kind == "paper"}


STUDIES: dict[str, tuple[str, ...]] = study_axes()
TOP_KEYS = {"study", "description", "base", "scenes", "seeds", "later_seeds", "mode", "axes", "sweeps", "extra_cells"}
BASE_KEYS = {"method", "preset", "set"}


@dataclass
class SceneSpec:
    """A scene of a grid: a synthetic preset (generated once per RUNS_DIR) or a folder."""

    preset: Optional[str] = None
    path: Optional[str] = None
    seed: int = 0
    views: Optional[int] = None
    resolution: Optional[list] = None

    @property
    def label(self) -> str:
        if self.preset:
            return self.folder_name()
        return Path(self.path or "").name

    def folder_name(self) -> str:
        name = f"{self.preset}-{self.seed}"
        if self.resolution:
            name += f"-{self.resolution[0]}x{self.resolution[1]}"
        if self.views:
            name += f"-v{self.views}"
        return name

    def to_dict(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if v is not None}


@dataclass
class Cell:
    """One grid cell before its config is resolved."""

    study: str
    method: str
    preset: Optional[str]
    overrides: dict[str, Any]     # dotted key -> value (base.set, then axis values)
    scene: SceneSpec
    seed: int
    axes: dict[str, Any]          # the axis values this cell sets explicitly


@dataclass
class Grid:
    name: str
    study: str
    path: Optional[Path]
    method: str
    preset: Optional[str]
    base_set: dict[str, Any]
    scenes: list[SceneSpec]
    seeds: list[int]
    blocks: list[tuple[str, dict[str, list]]]   # (mode, {axis key: values})
    extra_cells: list[dict[str, Any]]
    description: str = ""
    axis_keys: list[str] = field(default_factory=list)
    later_seeds: list[int] = field(default_factory=list)   # seeds added after a first look at the results
    later_why: str = ""                                     # what the look saw (the page says it)

    def base_tree(self) -> dict:
        """default.yaml <- preset <- base.set (used to spot cells that repeat the base config)."""
        return load_tree(self.preset, self.base_set)

    def cells(self) -> list[Cell]:
        """All cells: scenes x seeds x (union of axis blocks + extra cells), duplicates removed."""
        combos: list[dict[str, Any]] = []
        for mode, axes in self.blocks:
            keys = list(axes)
            if not keys:
                continue
            if mode == "product":
                rows = itertools.product(*(axes[k] for k in keys))
            else:
                rows = zip(*(axes[k] for k in keys))
            combos.extend(dict(zip(keys, row)) for row in rows)
        combos.extend(dict(c) for c in self.extra_cells)
        if not combos:
            combos = [{}]
        base = flatten(self.base_tree())
        seen: set[str] = set()
        out: list[Cell] = []
        for scene in self.scenes:
            for seed in self.seeds:
                for combo in combos:
                    combo = dict(combo)
                    method = combo.pop("method", self.method)
                    overrides = dict(self.base_set)
                    overrides.update(combo)
                    overrides["seed"] = seed
                    axes = dict(combo)
                    if "method" in self.axis_keys:
                        axes["method"] = method
                    effective = {k: v for k, v in overrides.items() if base.get(k, object()) != v}
                    key = json.dumps([scene.to_dict(), seed, method, effective], sort_keys=True, default=str)
                    if key in seen:
                        continue
                    seen.add(key)
                    out.append(Cell(self.study, method, self.preset, overrides, scene, seed, axes))
        return out


def _as_list(value: Any, where: str) -> list:
    if not isinstance(value, list) or not value:
        raise InputError(f"{where}: expected a non-empty list, got {short_repr(value)}")
    return value


def _parse_scene(item: Any, where: str) -> SceneSpec:
    known_presets = set(synthetic.PRESETS)
    if isinstance(item, dict):
        unknown = set(item) - {"preset", "path", "seed", "views", "resolution"}
        if unknown:
            raise InputError(f"{where}: unknown scene keys {sorted(unknown)}")
        if bool(item.get("preset")) == bool(item.get("path")):
            raise InputError(f"{where}: a scene mapping needs exactly one of `preset` or `path`")
        res = item.get("resolution")
        if res is not None and (not isinstance(res, list) or len(res) != 2):
            raise InputError(f"{where}: resolution must be [width, height], got {short_repr(res)}")
        spec = SceneSpec(preset=item.get("preset"), path=item.get("path"), seed=int(item.get("seed", 0)),
                         views=item.get("views"), resolution=res)
    elif isinstance(item, str):
        if item in known_presets:
            spec = SceneSpec(preset=item)
        elif "/" in item or "$" in item or Path(item).exists():
            spec = SceneSpec(path=item)
        else:
            raise InputError(f"{where}: {short_repr(item)} is neither a synthetic preset "
                             f"({', '.join(sorted(known_presets))}) nor an existing folder "
                             "(write paths with a '/', e.g. ./myscene)")
    else:
        raise InputError(f"{where}: a scene is a preset name, a folder path or a mapping, got {short_repr(item)}")
    if spec.preset and spec.preset not in known_presets:
        raise InputError(
            f"{where}: unknown synthetic preset {spec.preset!r}; known: {', '.join(sorted(known_presets))}"
        )
    return spec


def find_grid(name_or_path: str | os.PathLike) -> Path:
    """A shipped grid name (gsbench/grids/<name>.yaml) or a path to a grid file."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") and p.exists():
        return p
    if p.exists() and p.is_file():
        return p
    shipped = GRID_DIR / f"{name_or_path}.yaml"
    if shipped.exists():
        return shipped
    names = sorted(q.stem for q in GRID_DIR.glob("*.yaml"))
    raise InputError(f"grid {str(name_or_path)!r}: no such file and not a shipped grid; shipped: {', '.join(names)}")


def shipped_grids() -> list[str]:
    return sorted(q.stem for q in GRID_DIR.glob("*.yaml"))


def load_grid(name_or_path: str | os.PathLike, extra_set: Optional[dict[str, Any]] = None) -> Grid:
    """Parse and validate a grid file; every error names the file and the offending key."""
    path = find_grid(name_or_path)
    where = str(path)
    raw = load_yaml_file(path)
    if not isinstance(raw, dict):
        raise InputError(f"{where}: a grid file is a YAML mapping")
    return parse_grid(raw, where=where, path=path, extra_set=extra_set)


def _grid_preset(preset: Any, path: Optional[Path], where: str) -> Optional[str]:
    """A shipped preset name, or a YAML path (relative to the working folder, else to the grid file)."""
    if preset is None:
        return None
    if not isinstance(preset, str):
        raise InputError(f"{where}: base.preset must be a preset name or a .yaml path, got {short_repr(preset)}")
    p = Path(preset)
    if p.suffix in (".yaml", ".yml") and not p.is_absolute() and not p.is_file() and path is not None:
        p = Path(path).parent / p
    try:
        if p.suffix in (".yaml", ".yml"):
            return str(preset_path(p.resolve()))
        preset_path(preset)
        return preset
    except InputError as e:
        raise InputError(f"{where}: base.preset: {e}") from None


def _parse_seeds(raw: dict, where: str) -> tuple[list[int], list[int], str]:
    """(seeds, the seeds added after a first look, why): `later_seeds: {seeds: [..], why: ".."}` declares
    seeds a grid got after its results were seen, so the page can say which verdicts had two looks."""
    seeds = _as_list(raw.get("seeds", [0]), f"{where}: seeds")
    if not all(isinstance(s, int) and not isinstance(s, bool) for s in seeds):
        raise InputError(f"{where}: seeds must be integers, got {short_repr(seeds)}")
    later = raw.get("later_seeds")
    if later is None:
        return [int(s) for s in seeds], [], ""
    if not isinstance(later, dict) or set(later) != {"seeds", "why"}:
        raise InputError(f"{where}: later_seeds must be a mapping {{seeds: [...], why: '...'}}, "
                         f"got {short_repr(later)}")
    added, why = _as_list(later["seeds"], f"{where}: later_seeds.seeds"), later["why"]
    if not added or any(s not in seeds for s in added) or len(added) == len(seeds):
        raise InputError(f"{where}: later_seeds.seeds {short_repr(added)} must be some, not all, of seeds "
                         f"{short_repr(seeds)}")
    if not isinstance(why, str) or not why.strip():
        raise InputError(f"{where}: later_seeds.why must say what the first look saw")
    return [int(s) for s in seeds], [int(s) for s in added], why.strip()


def parse_grid(raw: dict, where: str = "<grid>", path: Optional[Path] = None,
               extra_set: Optional[dict[str, Any]] = None) -> Grid:
    unknown = set(raw) - TOP_KEYS
    if unknown:
        raise InputError(f"{where}: unknown top-level keys {sorted(unknown)}; allowed: {sorted(TOP_KEYS)}")
    tree = default_tree()
    leaves = flatten(tree)
    study = raw.get("study")
    if not isinstance(study, str) or not study:
        raise InputError(f"{where}: `study` (a name) is required")
    base = raw.get("base") or {}
    if not isinstance(base, dict):
        raise InputError(f"{where}: `base` must be a mapping")
    if set(base) - BASE_KEYS:
        raise InputError(f"{where}: unknown base keys {sorted(set(base) - BASE_KEYS)}; allowed: {sorted(BASE_KEYS)}")
    method = check_value("method", base.get("method", tree.get("method")), leaves, f"{where}: base.method")
    preset = _grid_preset(base.get("preset"), path, where)
    if base.get("set") is not None and not isinstance(base["set"], dict):
        raise InputError(f"{where}: base.set must be a mapping of config key -> value")
    base_set = {k: check_value(k, v, leaves, f"{where}: base.set")
                for k, v in parse_overrides(base.get("set"), f"{where}: base.set").items()}
    extra_set = {k: check_value(k, v, leaves, "--set") for k, v in (extra_set or {}).items()}
    base_set.update(extra_set)
    scenes = [
        _parse_scene(s, f"{where}: scenes[{i}]") for i, s in enumerate(_as_list(raw.get("scenes"), f"{where}: scenes"))
    ]
    seeds, later, later_why = _parse_seeds(raw, where)

    blocks: list[tuple[str, dict[str, list]]] = []
    if raw.get("axes"):
        blocks.append((raw.get("mode", "product"), raw["axes"]))
    elif "mode" in raw:
        raise InputError(f"{where}: `mode` given without `axes`")
    for i, sw in enumerate(raw.get("sweeps") or []):
        if not isinstance(sw, dict) or set(sw) - {"mode", "axes"} or not sw.get("axes"):
            raise InputError(f"{where}: sweeps[{i}] must be a mapping {{mode, axes}} with non-empty axes")
        blocks.append((sw.get("mode", "product"), sw["axes"]))
    axis_keys: list[str] = []
    for bi, (mode, axes) in enumerate(blocks):
        bw = f"{where}: axes" if bi == 0 and raw.get("axes") else f"{where}: sweeps"
        if mode not in ("product", "zip"):
            raise InputError(f"{bw}: mode must be product or zip, got {short_repr(mode)}")
        if not isinstance(axes, dict):
            raise InputError(f"{bw}: axes must be a mapping of config key -> list of values")
        for k, values in list(axes.items()):
            if k == "seed":
                raise InputError(f"{bw}: vary seeds with the top-level `seeds` list, not an axis")
            axes[k] = [check_value(k, v, leaves, bw) for v in _as_list(values, f"{bw}.{k}")]
            if k in base_set and extra_set and k in extra_set:
                raise InputError(f"--set {k}: conflicts with the grid axis {k} of {where}")
            if k not in axis_keys:
                axis_keys.append(k)
        if mode == "zip":
            lengths = {k: len(v) for k, v in axes.items()}
            if len(set(lengths.values())) > 1:
                raise InputError(f"{bw}: zip axes need equal lengths, got {lengths}")
    extra_cells = raw.get("extra_cells") or []
    if not isinstance(extra_cells, list):
        raise InputError(f"{where}: extra_cells must be a list of mappings")
    for i, c in enumerate(extra_cells):
        if not isinstance(c, dict) or not c:
            raise InputError(f"{where}: extra_cells[{i}] must be a non-empty mapping of config key -> value")
        for k, v in list(c.items()):
            c[k] = check_value(k, v, leaves, f"{where}: extra_cells[{i}]")
            if k not in axis_keys:
                axis_keys.append(k)
    axes_of = study_axes()
    if study in axes_of:
        allowed = set(axes_of[study])
        stray = [k for k in axis_keys if k not in allowed]
        if stray:
            raise InputError(f"{where}: study {study!r} varies {sorted(allowed)}; axis keys {stray} belong to no study "
                             "axis (use another study name for a custom grid)")
    name = path.stem if path is not None else study
    return Grid(name=name, study=study, path=path, method=method, preset=preset, base_set=base_set,
                scenes=scenes, seeds=seeds, blocks=blocks, extra_cells=extra_cells,
                description=str(raw.get("description", "")), axis_keys=axis_keys, later_seeds=later,
                later_why=later_why)


