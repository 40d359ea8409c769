"""Gather every results.json under a runs folder into one long table (one row per run and metric).

Why a long table: ablation grids vary different axes, and a report needs to slice runs by any of
them; one row per (run, metric) with one `axis.<key>` column per grid axis is the simplest shape
that pandas can pivot into every table of the paper.

Columns (what the reports read, plus a few extras):
  run_id, run_dir, study, method, scene, seed, status, protocol, backend,
  provider.depth, provider.masks, provider.features (and provider.<other> when results carry it),
  axis.<key> for every grid axis seen in any run - the value in the RESOLVED config (what the run
  really used: a loss the resolver switched off reads False even when the grid asked for True),
  requested.<key> (the value the grid asked for), dropped ("key: reason; ..." of what the resolver
  left out, "" when nothing), metric, value (float, NaN = not computed), metric_impl,
  extras: protocols (comma-joined list of the protocols the run was evaluated under),
  reason (why the value is missing: results' `skipped` entry of that metric name), source ("metrics" | "timings" |
  "memory"), config_key (gsbench.config.config_key: the canonical config without its seed: runs that
  differ only by seed share it), machine.<key> (host, cpu, cores, torch, ...), env.<key>
  (git_sha, platform, ... from the run's env.json when it exists: provenance only).

Timings (train_s, eval_s, render_ms, ...) and memory (peak_rss_mb, ...) become rows too, so that
the latent-d table can read them like any metric. Written as runs_dir/collected.parquet
(pyarrow); when pyarrow is not importable, as collected.csv, and the caller is told which.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any, Optional

import pandas as pd

from gsbench import rundir
from gsbench.config import config_key, upgrade_config, upgrade_key
from gsbench.errors import InputError, shorten
from gsbench.metric_table import KNOWN_METRICS
from gsbench.results import RESULTS_VERSION, check_shape
from gsbench.store import read_json, write_bytes_atomic, write_text_atomic

BASE_COLUMNS = [
    "run_id", "run_dir", "study", "method", "scene", "seed", "status", "protocol", "backend",
    "provider.depth", "provider.masks", "provider.features", "dropped",
]
TAIL_COLUMNS = ["metric", "value", "metric_impl", "reason", "source", "config_key"]
COLLECTED_PARQUET = "collected.parquet"
COLLECTED_CSV = "collected.csv"


def find_results(runs_dir: Path) -> list[Path]:
    """Every results.json under runs_dir (sorted), skipping hidden folders such as caches."""
    runs_dir = Path(runs_dir)
    if not runs_dir.exists():
        raise FileNotFoundError(f"{runs_dir}: runs folder not found")
    if not runs_dir.is_dir():
        raise NotADirectoryError(f"{runs_dir}: not a folder")
    out = []
    for p in sorted(runs_dir.rglob(rundir.RESULTS)):
        rel = p.relative_to(runs_dir).parts
        if any(part.startswith(".") for part in rel[:-1]):
            continue
        out.append(p)
    return out


def number_problem(value: Any) -> Optional[str]:
    """Why `value`, read from a JSON file, is not a number a reader may compute with (a finite int or
    float within float range, or null), in a few words that never echo a long value; None when it is."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"a {type(value).__name__} ({shorten(repr(value), 40)})"
    if isinstance(value, int) and abs(value) > sys.float_info.max:     # compared exactly: no overflow
        return f"an integer of {len(str(abs(value)))} digits, beyond the float range"
    if isinstance(value, float) and not math.isfinite(value):
        return f"{value} (not finite)"
    return None


def _as_float(value: Any, path: Path, what: str) -> float:
    """A stored number as a float (null: NaN); anything else an InputError naming the file and key."""
    why = number_problem(value)
    if why is not None and not (isinstance(value, float) and not math.isfinite(value)):
        raise InputError(f"{shorten(path)}: {shorten(what, 80)} must be a number or null, got {why}")
    if value is None:
        return math.nan
    v = float(value)
    return v if math.isfinite(v) else math.nan


def check_results_version(res: Any, path: Path) -> None:
    """A results.json of a newer results version than this gsbench reads is refused, naming the file."""
    version = res.get("results_version") if isinstance(res, dict) else None
    if version is not None and (isinstance(version, bool) or not isinstance(version, int)
                                or not 1 <= version <= RESULTS_VERSION):
        raise InputError(f"{shorten(path)}: results version {shorten(repr(version), 40)}; this gsbench reads "
                         f"versions 1 to {RESULTS_VERSION} (a newer gsbench wrote it?)")


def _scalar(value: Any) -> Any:
    """Grid axis / machine values are scalars; anything else is kept as its JSON text."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return json.dumps(value, sort_keys=True)


def missing_reason(metric: str, skipped: dict, status: str) -> str:
    """Why `metric` has no value: results' `skipped` entry under that metric name, else the run
    status, else "no reason recorded"."""
    if metric in skipped:
        return str(skipped[metric])
    if status != "done":
        return f"run {status}"
    return "no reason recorded"


def dropped_text(dropped: Any) -> str:
    """The resolver's {key: reason} as one cell: "key: reason; ..." sorted by key, "" when none."""
    if not dropped:
        return ""
    if not isinstance(dropped, dict):
        return str(dropped)
    return "; ".join(f"{k}: {v}" for k, v in sorted(dropped.items()))


_MISSING = object()


def _config_value(config: Any, dotted: str) -> Any:
    """The value at a dotted key of the resolved config, or _MISSING."""
    node = config
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            return _MISSING
        node = node[part]
    return node


ENV_KEYS = ("git_sha", "gsbench", "platform")


def _read_env(path: Path) -> dict:
    """The run's env.json (versions, git sha), when present: provenance for the report."""
    if not path.exists():
        return {}
    env = read_json(path)
    if not isinstance(env, dict):
        raise InputError(f"{path}: env.json must hold a JSON object")
    return env


def _rows_for(path: Path, res: Any, known_metrics: set[str]) -> list[dict]:
    check_shape(res, path)
    check_results_version(res, path)
    metrics = res.get("metrics") or {}
    skipped = res.get("skipped") or {}
    grid = res.get("grid") or {}
    providers = res.get("providers") or {}
    machine = res.get("machine") or {}
    metric_impl = res.get("metric_impl") or {}
    status = str(res.get("status") or "done")
    seed = res.get("seed")

    base: dict[str, Any] = {
        "run_id": str(res["run_id"]),
        "run_dir": str(path.parent),
        "study": res.get("study"),
        "method": str(res["method"]),
        "scene": str(res["scene"]),
        "seed": seed,
        "status": status,
        "protocol": res.get("protocol"),
        "protocols": ",".join(
            str(p) for p in res.get("protocols") or ([res["protocol"]] if res.get("protocol") else [])
        ),
        "backend": res.get("backend"),
        "provider.depth": providers.get("depth"),
        "provider.masks": providers.get("masks"),
        "provider.features": providers.get("features"),
        "dropped": dropped_text(res.get("dropped")),
        "config_key": config_key(res.get("config")),
    }
    for k, v in providers.items():
        if f"provider.{k}" not in base:
            base[f"provider.{k}"] = _scalar(v)
    for k, v in grid.items():
        resolved = _config_value(res.get("config"), k)
        base[f"axis.{k}"] = _scalar(v if resolved is _MISSING else resolved)
        base[f"requested.{k}"] = _scalar(v)
    for k, v in machine.items():
        base[f"machine.{k}"] = _scalar(v)
    env = _read_env(path.parent / rundir.ENV)
    for k in ENV_KEYS:
        if k in env:
            base[f"env.{k}"] = _scalar(env[k])

    entries: list[tuple[str, Any, str]] = [(m, v, "metrics") for m, v in metrics.items()]
    present = set(metrics)
    for section in ("timings", "memory"):
        block = res.get(section) or {}
        for m, v in block.items():
            # descriptive entries (e.g. "fps_sync": "none (cpu, synchronous)") are not quantities
            if isinstance(v, (str, bool, dict, list)):
                continue
            if m not in present:
                entries.append((m, v, section))
                present.add(m)
    # A metric the evaluation skipped without writing a null still gets a row with its reason.
    for m in sorted(known_metrics):
        if m not in present and m in skipped:
            entries.append((m, None, "metrics"))
            present.add(m)

    rows = []
    for m, v, source in entries:
        value = _as_float(v, path, f"{source}.{m}")
        row = dict(base)
        row["metric"] = str(m)
        row["value"] = value
        impl = metric_impl.get(m) if isinstance(metric_impl, dict) else None
        row["metric_impl"] = str(impl) if impl is not None else (source if source != "metrics" else None)
        row["reason"] = missing_reason(str(m), skipped, status) if math.isnan(value) else None
        row["source"] = source
        rows.append(row)
    if not rows:  # a run with no metrics at all still shows up (status, reason)
        row = dict(base)
        row.update(metric=None, value=math.nan, metric_impl=None, source=None,
                   reason=missing_reason("", skipped, status))
        rows.append(row)
    return rows


def upgraded_results(res: Any) -> Any:
    """A results.json written before a method moved keys, read in today's layout (its config and its grid
    axis keys: gsbench.config.upgrade_config), so old runs sit in the same columns as new ones."""
    config = upgrade_config(res.get("config")) if isinstance(res, dict) else None
    if config is None or config is res.get("config"):
        return res
    grid = res.get("grid")
    grid = {upgrade_key(str(k)): v for k, v in grid.items()} if isinstance(grid, dict) else grid
    return {**res, "config": config, "grid": grid}


def _unreadable_row(path: Path, error: str) -> dict:
    """The row of a run whose results.json cannot be read: status "failed", the error as reason.

    Identity comes from the run's config.json when that one is readable, else from the folder name."""
    config: Any = {}
    try:
        if (path.parent / rundir.CONFIG).exists():
            config = read_json(path.parent / rundir.CONFIG)
    except InputError:
        pass
    config = config if isinstance(config, dict) else {}
    scene = config.get("scene")
    seed = config.get("seed")
    return {
        "run_id": str(config.get("run_id") or path.parent.name), "run_dir": str(path.parent),
        "study": config.get("study"), "method": config.get("method"),
        "scene": scene.get("name") if isinstance(scene, dict) else None,
        "seed": seed if isinstance(seed, int) and not isinstance(seed, bool) else None,
        "status": "failed", "protocol": None, "protocols": "", "backend": config.get("backend"),
        "provider.depth": None, "provider.masks": None, "provider.features": None,
        "dropped": dropped_text(config.get("dropped")), "config_key": config_key(config or None),
        "metric": None, "value": math.nan, "metric_impl": None, "source": None,
        "reason": f"results.json unreadable: {error}",
    }


def _normalise_axis(col: pd.Series) -> pd.Series:
    """One type per axis column (Parquet needs it): numbers -> float, booleans -> boolean, else str."""
    vals = [v for v in col.tolist() if v is not None and not (isinstance(v, float) and math.isnan(v))]
    if vals and all(isinstance(v, bool) for v in vals):
        return col.astype("boolean")
    if vals and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
        return pd.to_numeric(col, errors="raise").astype("float64")
    return col.map(lambda v: None if v is None or (isinstance(v, float) and math.isnan(v)) else str(v)).astype(object)


def collect(runs_dir: str | Path) -> pd.DataFrame:
    """Read every results.json under runs_dir into the long table (no file written).

    Runs found twice (same run_id in two folders, e.g. a copied run) are kept once, the first in
    path order; the duplicates are listed in `df.attrs["warnings"]`. A results.json that cannot be
    read (truncated, not the schema) becomes one failed row with the error as its reason and is
    listed in `df.attrs["unreadable"]`; when no file can be read at all, that is an InputError.
    """
    runs_dir = Path(runs_dir)
    paths = find_results(runs_dir)
    if not paths:
        raise InputError(f"{runs_dir}: no results.json found (evaluate runs with `gsbench eval` first)")
    rows: list[dict] = []
    seen: dict[str, Path] = {}
    warnings: list[str] = []
    unreadable: list[str] = []
    for p in paths:
        try:
            res = read_json(p)
            run_id = str(res.get("run_id")) if isinstance(res, dict) else None
            if run_id is not None and run_id in seen:
                warnings.append(f"{p}: run_id {run_id} already read from {seen[run_id]}; duplicate ignored")
                continue
            rows.extend(_rows_for(p, upgraded_results(res), KNOWN_METRICS))
        except InputError as e:  # one bad file never hides the other runs: it becomes a failed row
            unreadable.append(str(e))
            warnings.append(f"could not read {e}")
            run_id = None
            rows.append(_unreadable_row(p, str(e)))
        if run_id is not None:
            seen[run_id] = p
    if unreadable and len(unreadable) == len(paths):
        more = f" (and {len(unreadable) - 1} more)" if len(unreadable) > 1 else ""
        raise InputError(f"{runs_dir}: no results.json could be read: {unreadable[0]}{more}")
    df = pd.DataFrame(rows)
    for c in BASE_COLUMNS + TAIL_COLUMNS:
        if c not in df.columns:
            df[c] = None
    axis_cols = sorted(c for c in df.columns if c.startswith("axis."))
    other = sorted(c for c in df.columns if c not in BASE_COLUMNS + TAIL_COLUMNS + axis_cols)
    df = df[BASE_COLUMNS + axis_cols + TAIL_COLUMNS + other].copy()
    for c in axis_cols:
        df[c] = _normalise_axis(df[c])
    df["value"] = df["value"].astype("float64")
    df["seed"] = df["seed"].astype("Int64")
    for c in df.columns:
        if c.startswith(("machine.", "provider.", "env.", "requested.")):
            df[c] = (
                df[c]
                .map(lambda v: None if v is None or (isinstance(v, float) and math.isnan(v)) else str(v))
                .astype(object)
            )
        elif c not in ("value", "seed") and not c.startswith("axis."):
            df[c] = _objects(df[c])
    df.attrs["warnings"] = warnings
    df.attrs["unreadable"] = unreadable
    df.attrs["runs_dir"] = str(runs_dir)
    return df


def write_collected(df: pd.DataFrame, runs_dir: str | Path) -> Path:
    """Write the long table next to the runs: Parquet when pyarrow is importable, else CSV."""
    runs_dir = Path(runs_dir)
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        out = runs_dir / COLLECTED_CSV
        write_text_atomic(out, df.to_csv(index=False))
        return out
    import io
    buf = io.BytesIO()
    plain = df.copy()
    plain.attrs = {}
    plain.to_parquet(buf, engine="pyarrow", index=False)
    out = runs_dir / COLLECTED_PARQUET
    write_bytes_atomic(out, buf.getvalue())
    return out


def read_collected(path: str | Path) -> pd.DataFrame:
    """Read a collected.parquet / collected.csv written by `write_collected`."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: collected table not found")
    try:
        if path.suffix == ".parquet":
            df = pd.read_parquet(path, engine="pyarrow")
        elif path.suffix == ".csv":
            df = pd.read_csv(path)
        else:
            raise InputError(f"{path}: expected a .parquet or .csv collected table")
    except InputError:
        raise
    except Exception as e:
        raise InputError(f"{path}: cannot read collected table ({type(e).__name__}: {e})") from None
    missing = [c for c in BASE_COLUMNS + ["metric", "value"] if c not in df.columns]
    if missing:
        raise InputError(f"{path}: not a gsbench collected table (missing columns {missing})")
    for c in TAIL_COLUMNS:
        if c not in df.columns:
            df[c] = None
    # Back to plain Python objects (None for missing) so both formats behave the same.
    for c in df.columns:
        if c in ("value",):
            df[c] = pd.to_numeric(df[c], errors="coerce").astype("float64")
        elif c == "seed":
            df[c] = pd.to_numeric(df[c], errors="coerce").astype("Int64")
        elif c.startswith("axis."):
            col = df[c].astype(object).where(df[c].notna(), None)
            if path.suffix == ".csv":
                col = col.map(_csv_scalar)
            df[c] = _normalise_axis(col)
        else:
            df[c] = _objects(df[c])
    df.attrs["warnings"] = []
    df.attrs["runs_dir"] = str(path.parent)
    return df


def _objects(col: pd.Series) -> pd.Series:
    """Plain Python objects with None for missing (pandas would otherwise turn None into NaN)."""
    out = col.astype(object)
    return out.where(col.notna(), None)


def _csv_scalar(v: Any) -> Any:
    if isinstance(v, str):
        if v in ("True", "False"):
            return v == "True"
        try:
            return float(v)
        except ValueError:
            return v
    return v
