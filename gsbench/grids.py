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
"failed", null metrics and the error in `skipped["run"]` (so reports show "n/a (run failed)" instead
of "no run"); it stays failed on a re-run and `--retry-failed` runs it again.
"""
from __future__ import annotations

import copy
import difflib
import itertools
import json
import os
import socket
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Optional

import yaml

from gsbench.errors import InputError
from gsbench.store import read_json, write_json_atomic

CONFIG_DIR = Path(__file__).parent / "configs"
GRID_DIR = Path(__file__).parent / "grids"
CACHE_DIRNAME = ".gsbench_cache"
SCENES_DIRNAME = "scenes"
CELL_FILE = "cell.json"
CELL_STATUS_FILE = "cell_status.json"
HEARTBEAT_S = 10.0
STALE_AFTER_S = 120.0

# Study names and the axis keys they vary (gsbench/store.py docstring is the contract).
STUDIES: dict[str, tuple[str, ...]] = {
    "reconstruction": ("method",),
    "ordering": ("priors.ordering",),
    "depth_formulation": ("gaussiands.depth_formulation",),
    "loss_subsets": ("gaussiands.losses.depth", "gaussiands.losses.tv", "gaussiands.losses.ds"),
    "latent_dim": ("gaussiands.latent_dim", "method"),
    "lambda_grid": ("gaussiands.lambdas.depth", "gaussiands.lambdas.tv", "gaussiands.lambdas.sem",
                    "gaussiands.lambdas.ds"),
    "depth_noise": ("priors.depth.noise.type", "priors.depth.noise.severity"),
}
TOP_KEYS = {"study", "description", "base", "scenes", "seeds", "mode", "axes", "sweeps", "extra_cells"}
BASE_KEYS = {"method", "preset", "set"}


# ----------------------------------------------------------------------------- config tree
def default_tree() -> dict:
    """The default config tree (key names are the contract grid axes are checked against)."""
    with open(CONFIG_DIR / "default.yaml", encoding="utf-8") as f:
        return yaml.safe_load(f)


def flatten(tree: dict, prefix: str = "") -> dict[str, Any]:
    """Leaves of a nested dict as {dotted.key: value}."""
    out: dict[str, Any] = {}
    for k, v in tree.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and v:
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out


def get_dotted(tree: dict, key: str) -> Any:
    node: Any = tree
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            raise KeyError(key)
        node = node[part]
    return node


def set_dotted(tree: dict, key: str, value: Any) -> None:
    parts = key.split(".")
    node = tree
    for part in parts[:-1]:
        node = node.setdefault(part, {})
    node[parts[-1]] = value


def check_key(key: str, leaves: dict[str, Any], where: str) -> None:
    """An unknown config key is an InputError naming the closest valid keys."""
    if key in leaves:
        return
    close = difflib.get_close_matches(key, list(leaves), n=3, cutoff=0.5)
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    raise InputError(f"{where}: unknown config key {key!r} (not in gsbench/configs/default.yaml){hint}")


def check_value(key: str, value: Any, default: Any, where: str) -> None:
    """Catch the common typo of a quoted bool/number; a null default accepts anything."""
    if default is None or value is None:
        return
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise InputError(f"{where}: {key} must be true/false, got {value!r}")
    elif isinstance(default, (int, float)):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"{where}: {key} must be a number, got {value!r}")
    elif isinstance(default, str):
        if not isinstance(value, str):
            raise InputError(f"{where}: {key} must be a string, got {value!r}")
    elif isinstance(default, list):
        if not isinstance(value, list):
            raise InputError(f"{where}: {key} must be a list, got {value!r}")


def _merge(dst: dict, src: dict) -> None:
    for k, v in src.items():
        if isinstance(v, dict) and isinstance(dst.get(k), dict):
            _merge(dst[k], v)
        else:
            dst[k] = v


def parse_set(items: Iterable[str], where: str = "--set") -> dict[str, Any]:
    """`key.sub=value` strings -> {key.sub: YAML-parsed value}."""
    out: dict[str, Any] = {}
    for item in items:
        if "=" not in item:
            raise InputError(f"{where}: expected key=value, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = yaml.safe_load(v) if v.strip() else None
    return out


# ----------------------------------------------------------------------------- grid model
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

    def base_tree(self) -> dict:
        """default.yaml <- preset <- base.set (used to spot cells that repeat the base config)."""
        tree = default_tree()
        if self.preset:
            with open(CONFIG_DIR / f"{self.preset}.yaml", encoding="utf-8") as f:
                _merge(tree, yaml.safe_load(f) or {})
        for k, v in self.base_set.items():
            set_dotted(tree, k, v)
        return tree

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
        raise InputError(f"{where}: expected a non-empty list, got {value!r}")
    return value


def _parse_scene(item: Any, where: str) -> SceneSpec:
    known_presets = _known_presets()
    if isinstance(item, dict):
        unknown = set(item) - {"preset", "path", "seed", "views", "resolution"}
        if unknown:
            raise InputError(f"{where}: unknown scene keys {sorted(unknown)}")
        if bool(item.get("preset")) == bool(item.get("path")):
            raise InputError(f"{where}: a scene mapping needs exactly one of `preset` or `path`")
        res = item.get("resolution")
        if res is not None and (not isinstance(res, list) or len(res) != 2):
            raise InputError(f"{where}: resolution must be [width, height], got {res!r}")
        spec = SceneSpec(preset=item.get("preset"), path=item.get("path"), seed=int(item.get("seed", 0)),
                         views=item.get("views"), resolution=res)
    elif isinstance(item, str):
        if known_presets is not None and item in known_presets:
            spec = SceneSpec(preset=item)
        elif "/" in item or "$" in item or Path(item).exists():
            spec = SceneSpec(path=item)
        elif known_presets is None:
            spec = SceneSpec(preset=item)   # generator not importable: checked when the scene is made
        else:
            raise InputError(f"{where}: {item!r} is neither a synthetic preset ({', '.join(sorted(known_presets))}) "
                             "nor an existing folder (write paths with a '/', e.g. ./myscene)")
    else:
        raise InputError(f"{where}: a scene is a preset name, a folder path or a mapping, got {item!r}")
    if spec.preset and known_presets is not None and spec.preset not in known_presets:
        raise InputError(f"{where}: unknown synthetic preset {spec.preset!r}; known: {', '.join(sorted(known_presets))}")
    return spec


def _known_presets() -> Optional[set[str]]:
    try:
        from gsbench.datasets import synthetic
    except ImportError:
        return None
    presets = getattr(synthetic, "PRESETS", None)
    return set(presets) if presets is not None else None


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
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as e:
        raise InputError(f"{where}: invalid YAML ({e})") from None
    if not isinstance(raw, dict):
        raise InputError(f"{where}: a grid file is a YAML mapping")
    return parse_grid(raw, where=where, path=path, extra_set=extra_set)


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
    method = base.get("method", tree.get("method"))
    preset = base.get("preset")
    if preset is not None and not (CONFIG_DIR / f"{preset}.yaml").exists():
        presets = sorted(p.stem for p in CONFIG_DIR.glob("*.yaml") if p.stem != "default")
        raise InputError(f"{where}: unknown config preset {preset!r}; known: {', '.join(presets)}")
    base_set = dict(base.get("set") or {})
    if extra_set:
        base_set.update(extra_set)
    for k, v in base_set.items():
        check_key(k, leaves, f"{where}: base.set")
        check_value(k, v, leaves[k], f"{where}: base.set")
    scenes = [_parse_scene(s, f"{where}: scenes[{i}]") for i, s in enumerate(_as_list(raw.get("scenes"), f"{where}: scenes"))]
    seeds = raw.get("seeds", [0])
    seeds = _as_list(seeds, f"{where}: seeds")
    if not all(isinstance(s, int) and not isinstance(s, bool) for s in seeds):
        raise InputError(f"{where}: seeds must be integers, got {seeds!r}")

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
            raise InputError(f"{bw}: mode must be product or zip, got {mode!r}")
        if not isinstance(axes, dict):
            raise InputError(f"{bw}: axes must be a mapping of config key -> list of values")
        for k, values in axes.items():
            check_key(k, leaves, bw)
            if k == "seed":
                raise InputError(f"{bw}: vary seeds with the top-level `seeds` list, not an axis")
            for v in _as_list(values, f"{bw}.{k}"):
                check_value(k, v, leaves[k], f"{bw}.{k}")
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
        for k, v in c.items():
            check_key(k, leaves, f"{where}: extra_cells[{i}]")
            check_value(k, v, leaves[k], f"{where}: extra_cells[{i}]")
            if k not in axis_keys:
                axis_keys.append(k)
    if study in STUDIES:
        allowed = set(STUDIES[study])
        stray = [k for k in axis_keys if k not in allowed]
        if stray:
            raise InputError(f"{where}: study {study!r} varies {sorted(allowed)}; axis keys {stray} belong to no study "
                             "axis (use another study name for a custom grid)")
    name = path.stem if path is not None else study
    return Grid(name=name, study=study, path=path, method=method, preset=preset, base_set=base_set,
                scenes=scenes, seeds=[int(s) for s in seeds], blocks=blocks, extra_cells=extra_cells,
                description=str(raw.get("description", "")), axis_keys=axis_keys)


# ----------------------------------------------------------------------------- scenes
def resolve_scene(spec: SceneSpec, runs_dir: Path, create: bool = True) -> Optional[Path]:
    """A scene folder for `spec`: presets are generated once into RUNS_DIR/scenes/<preset>-<seed>
    (into a temp folder renamed into place, so concurrent or killed runs never see half a scene).
    With create=False a missing preset scene gives None."""
    if spec.path:
        p = Path(os.path.expandvars(os.path.expanduser(spec.path)))
        if "$" in str(p):
            raise InputError(f"scene {spec.path!r}: unset environment variable in the path")
        if not p.is_dir():
            raise InputError(f"scene {p}: folder not found")
        return p.resolve()
    out = (runs_dir / SCENES_DIRNAME / spec.folder_name()).resolve()
    if out.is_dir():
        return out
    if not create:
        return None
    from gsbench.datasets.synthetic import make_scene
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
    from gsbench.config import load_config
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


def plan(grid: Grid, runs_dir: Path, create_scenes: bool = True) -> list[PlannedCell]:
    """Resolve scenes (generating presets once), configs and run ids of every cell."""
    from gsbench.config import run_id as make_run_id
    from gsbench.datasets import scene_fingerprint
    runs_dir = Path(runs_dir)
    scene_paths: dict[str, Optional[Path]] = {}
    fingerprints: dict[str, str] = {}
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
        rid = make_run_id(config, fingerprints[skey])
        if rid in seen_ids:
            continue   # the same resolved config reached through two sweeps
        seen_ids.add(rid)
        out.append(PlannedCell(cell, config, sp, rid, runs_dir / rid))
    return out


# ----------------------------------------------------------------------------- status
def pid_alive(pid: int) -> bool:
    """True when `pid` is a live process. A zombie (killed, not yet reaped: workers of a killed
    grid are re-parented to an init that may never reap them) counts as dead."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True   # no /proc (not Linux): trust kill(0)
    # the state letter follows the parenthesised command name, which may itself contain spaces
    return stat[stat.rfind(")") + 2:][:1] not in ("Z", "X")


def read_cell_status(run_dir: Path) -> dict:
    p = Path(run_dir) / CELL_STATUS_FILE
    if not p.exists():
        return {"state": "pending"}
    try:
        return read_json(p)
    except ValueError:
        return {"state": "pending", "note": "unreadable cell_status.json"}


def cell_state(run_dir: Optional[Path], now: Optional[float] = None) -> str:
    """pending | running | stale | done | failed. `stale` = marked running but its process is gone
    (same host, pid dead) or its heartbeat is older than STALE_AFTER_S."""
    if run_dir is None:
        return "pending"
    st = read_cell_status(run_dir)
    state = st.get("state", "pending")
    if state == "done":
        return "done" if results_finished(run_dir) else "stale"
    if state == "running":
        now = time.time() if now is None else now
        if st.get("host") == socket.gethostname() and st.get("pid") and not pid_alive(int(st["pid"])):
            return "stale"
        if now - float(st.get("heartbeat", 0)) > STALE_AFTER_S:
            return "stale"
        return "running"
    return state if state in ("failed", "pending") else "pending"


def results_finished(run_dir: Path) -> bool:
    """results.json exists, is readable and is not a failure record (status "failed")."""
    p = Path(run_dir) / "results.json"
    if not p.exists():
        return False
    try:
        res = read_json(p)
    except ValueError:
        return False
    return isinstance(res, dict) and res.get("status") != "failed"


# Metrics a failed cell records as null (gsbench.store METRIC NAMES), so every table has its row.
FAILED_METRICS = ("psnr", "ssim", "lpips", "fps", "miou_3dovs", "mbiou_3dovs", "pixel_acc_3dovs",
                  "miou_lerf", "loc_acc_lerf", "removal_residual", "removal_psnr_outside",
                  "ordering_adjacent_distance", "ordering_adjacent_mask_iou")


def write_failed_results(spec: dict, run_dir: Path, status: dict) -> dict:
    """results.json of a failed cell (schema: gsbench.store): status "failed", every metric null and
    the error in skipped["run"]. Identity fields come from the run's config.json when training got
    that far (the resolved config), else from the cell's config."""
    from gsbench.evaluate import machine_info
    from gsbench.store import RESULTS_VERSION
    cfg_path = run_dir / "config.json"
    config = spec.get("config") or {}
    try:
        if cfg_path.exists():
            config = read_json(cfg_path)
    except ValueError:
        pass
    scene_name, protocols = None, []
    try:   # name and protocols as evaluate_run would record them, so the failed cell shares their columns
        from gsbench.datasets import load_scene
        from gsbench.evaluate import resolve_protocols
        scene = load_scene(spec["scene_path"])
        scene_name = scene.name or Path(scene.path).name
        protocols, _ = resolve_protocols(scene, "auto")
    except Exception:  # the scene itself may be what failed; its folder name identifies it
        pass
    scene_name = scene_name or Path(str(spec.get("scene_path"))).name
    reason = f"run failed (attempt {status.get('attempt')}): {status.get('error', 'unknown error')}"
    results = {
        "results_version": RESULTS_VERSION, "run_id": run_dir.name, "method": config.get("method", spec.get("method")),
        "scene": scene_name, "scene_path": str(spec.get("scene_path")), "seed": config.get("seed", spec.get("seed")),
        "study": config.get("study", spec.get("study")), "grid": config.get("grid") or {}, "config": config,
        "providers": {"depth": None, "masks": None, "features": None}, "backend": None,
        "protocol": protocols[0] if protocols else None, "protocols": protocols, "metric_impl": {},
        "metrics": {m: None for m in FAILED_METRICS}, "per_view": {}, "view_names": [],
        "skipped": {"run": reason}, "timings": {"train_s": None, "eval_s": None, "cell_wall_s": status.get("wall_s")},
        "memory": {}, "machine": machine_info(), "status": "failed", "dropped": config.get("dropped", {}),
    }
    write_json_atomic(run_dir / "results.json", results)
    return results


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
    is written to cell_status.json and returned), so one bad cell does not stop a grid."""
    run_dir = Path(spec["run_dir"])
    run_dir.mkdir(parents=True, exist_ok=True)
    prev = read_cell_status(run_dir)
    status = {"state": "running", "pid": os.getpid(), "host": socket.gethostname(), "started": time.time(),
              "heartbeat": time.time(), "attempt": int(prev.get("attempt", 0)) + 1, "phase": "train",
              "resumed": (run_dir / "checkpoint.pt").exists()}
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
    from gsbench.evaluate import evaluate_run
    from gsbench.executors import apply_thread_budget
    status["torch_threads"] = apply_thread_budget()
    from gsbench.runs import train_run
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


def priors_request(spec: dict) -> Optional[dict]:
    """What the cell's method will ask gsbench.priors for (mirrors the fit() of each method: vanilla
    none; twostage per-frame masks + features; gaussiands depth and/or propagated masks + features),
    or None when it needs no priors. Cells with equal requests share one cache entry."""
    from gsbench.config import resolve_for_scene
    from gsbench.datasets import load_scene
    from gsbench.methods.base import training_size
    from gsbench.methods.common import uses
    scene = load_scene(spec["scene_path"])
    cfg, _ = resolve_for_scene(spec["config"], scene)
    if cfg["method"] == "vanilla" or not scene.train_ids:
        return None
    use = uses(cfg)
    if cfg["method"] == "twostage":
        need_depth, need_sem, per_frame = False, use["semantics"], True
    else:
        need_depth, need_sem, per_frame = use["depth_prior"], use["semantics"], False
    if not (need_depth or need_sem):
        return None
    w, h = training_size(scene.cameras[scene.train_ids[0]], cfg["train"].get("max_width"))
    return {"scene_path": spec["scene_path"], "priors": cfg["priors"], "view_ids": sorted(scene.train_ids),
            "size": [w, h], "need_depth": need_depth, "need_sem": need_sem, "per_frame": per_frame,
            "seed": int(cfg["seed"])}


def prepare_priors_job(request: dict) -> dict:
    """Compute one shared priors entry into the cache (run through the executor before the cells)."""
    t0 = time.time()
    try:
        from gsbench.datasets import load_scene
        from gsbench.executors import apply_thread_budget
        from gsbench.priors import prepare_priors
        apply_thread_budget()
        scene = load_scene(request["scene_path"])
        pri = prepare_priors(scene, request["priors"], request["view_ids"], tuple(request["size"]),
                             Path(request["priors"]["cache_dir"]), need_depth=request["need_depth"],
                             need_masks=request["need_sem"], need_features=request["need_sem"],
                             per_frame_masks=request["per_frame"], seed=request["seed"], progress=False)
        return {"ok": True, "seconds": time.time() - t0, "providers": dict(pri.providers)}
    except Exception as e:  # the cells then compute their own priors; the grid says so
        return {"ok": False, "seconds": time.time() - t0, "error": f"{type(e).__name__}: {e}"}


def shared_priors(todo: list[PlannedCell], executor: Any, log: Callable[[str], None]) -> dict:
    """Compute each priors entry that two or more pending cells share, once, before the cells run
    (so parallel cells never compute the same entry side by side)."""
    groups: dict[str, list[dict]] = {}
    for pc in todo:
        req = priors_request(pc.spec())
        if req is not None:
            groups.setdefault(json.dumps(req, sort_keys=True, default=str), []).append(req)
    shared = [reqs[0] for reqs in groups.values() if len(reqs) > 1]
    if not shared:
        return {"groups": 0}
    t0 = time.time()
    out = list(executor.map(prepare_priors_job, shared))
    bad = [r["error"] for r in out if not r["ok"]]
    log(f"shared priors: {len(shared)} entr{'y' if len(shared) == 1 else 'ies'} for "
        f"{sum(len(v) for v in groups.values() if len(v) > 1)} cells in {time.time() - t0:.1f} s"
        + (f"; {len(bad)} failed, those cells compute their own: {bad}" if bad else ""))
    return {"groups": len(shared), "seconds": time.time() - t0, "failed": bad}


def run_grid(grid: Grid, runs_dir: Path, executor: Any, retry_failed: bool = False,
             log: Callable[[str], None] = print, share_priors: bool = True) -> GridReport:
    """Plan the grid, skip finished cells, compute shared priors once, dispatch the remaining cells
    through `executor` (anything with `map(fn, items) -> list`), and return what happened."""
    runs_dir = Path(runs_dir)
    runs_dir.mkdir(parents=True, exist_ok=True)
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
    if todo and share_priors:
        shared_priors(todo, executor, log)
    results = executor.map(run_cell, [pc.spec() for pc in todo]) if todo else []
    return GridReport(planned, states, [pc.run_id for pc in todo], list(results))


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


def status_rows(runs_dir: Path, grid: Optional[Grid] = None) -> list[dict]:
    """One row per cell: from the grid's plan when given (cells never started are pending), else from
    every cell folder found under RUNS_DIR."""
    runs_dir = Path(runs_dir)
    rows = []
    if grid is not None:
        return planned_rows(plan(grid, runs_dir, create_scenes=False))
    for cj in sorted(runs_dir.glob(f"*/{CELL_FILE}")):
        try:
            spec = read_json(cj)
        except ValueError:
            continue
        scene = spec.get("scene", {})
        label = SceneSpec(**scene).label if scene else ""
        rows.append(_row(cj.parent.name, cj.parent, spec.get("method", ""), label, spec.get("seed"),
                         spec.get("axes", {})))
    return rows


def planned_rows(planned: list[PlannedCell]) -> list[dict]:
    """Status rows of planned cells (cells never started are pending)."""
    return [_row(pc.run_id, pc.run_dir, pc.cell.method, pc.cell.scene.label, pc.cell.seed, pc.config.get("grid", {}))
            for pc in planned]


def _row(run_id, run_dir, method, scene, seed, axes) -> dict:
    state = cell_state(run_dir) if run_dir is not None and Path(run_dir).exists() else "pending"
    st = read_cell_status(run_dir) if run_dir is not None else {}
    return {"run_id": run_id or "-", "state": state, "method": method, "scene": scene, "seed": seed,
            "axes": ", ".join(f"{k}={v}" for k, v in axes.items()), "wall_s": st.get("wall_s"),
            "attempt": st.get("attempt", 0), "error": st.get("error", "") if state == "failed" else ""}


def format_status(rows: list[dict]) -> str:
    """A plain-text table plus counts."""
    cols = ["state", "run_id", "method", "scene", "seed", "attempt", "wall_s", "axes", "error"]
    table = [[_fmt(r.get(c)) for c in cols] for r in rows]
    widths = [max([len(c)] + [len(t[i]) for t in table]) for i, c in enumerate(cols)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(cols, widths)).rstrip()]
    for t in table:
        lines.append("  ".join(v.ljust(w) for v, w in zip(t, widths)).rstrip())
    counts: dict[str, int] = {}
    for r in rows:
        counts[r["state"]] = counts.get(r["state"], 0) + 1
    lines.append(f"{len(rows)} cells: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    return "\n".join(lines)


def _fmt(v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.1f}"
    s = str(v)
    return s if len(s) <= 80 else s[:77] + "..."
