"""The results.json contract: its version, the metric names, and the two builders that write it.

One module so that the evaluation (normal runs, mask folders) and the grid runner (failed cells)
write the same schema, and the reports read names from here instead of the other way round.

results.json keys (reports read only these):
  results_version, run_id, method, scene, scene_path, seed, study, grid {axis: value}, config,
  providers {"depth", "masks", "features"}, backend, protocol, protocols [..], query_mode,
  metric_impl {metric: id}, metrics {metric: float | None}, per_view {metric: [float | None]}
  (in the order of the metric's frame set in `frames`), view_names [..] (the reconstruction views),
  skipped {metric: reason}  (every null metric has one; keys are metric names),
  notes {topic: text}  (what was left out that is not a metric: views without GT, ...),
  frames {frame set: [frame names]}, frames_skipped {frame name: reason},
  split {holdout, views, trained_ids, trained_names, held_out_ids, held_out_names} (the views the run
  trained on and held out, train.holdout and train.views; null for a scored mask folder or a failed cell),
  resolution {frame set: "WxH"}, timings, memory, machine, status, dropped.

Metric names are built from parts (see `METRIC_NAMES`): a segmentation metric is
<base>_<protocol>[_<query mode>][_heldout]; the plain name is the configured query mode on the
`reference` frame set (the frames the references score), `_heldout` the frames not trained on.
"""
from __future__ import annotations

import math
from typing import Any, Iterable, Optional

from gsbench.errors import InputError

from gsbench.metric_table import (DEPTH_METRICS, IMAGE_METRICS, INPUT_METRICS, KNOWN_METRICS,  # isort: skip
                                  ORDERING_METRICS, REMOVAL_METRICS, SEG_BASES, seg_metric)

RESULTS_VERSION = 2
STATUSES = ("done", "failed", "nonfinite")
def summarise(values: Iterable[Any], names: Optional[list[str]] = None) -> tuple[Optional[float], Optional[str]]:
    """(mean, None) of per-view values, or (None, reason) when any of them is missing or non-finite:
    a mean over the views that happened to work would be a different, unlabelled number."""
    vals = list(values)
    bad = [k for k, v in enumerate(vals) if v is None or not math.isfinite(float(v))]
    if not vals:
        return None, "no view to average"
    if bad:
        which = [names[k] for k in bad] if names is not None else bad
        return None, f"{len(bad)} of {len(vals)} views missing or non-finite: {which}"
    return math.fsum(float(v) for v in vals) / len(vals), None


def check_skipped(metrics: dict, skipped: dict) -> None:
    """Every null metric has a reason keyed by its name, and every reason names a metric."""
    unknown = sorted(k for k in skipped if k not in KNOWN_METRICS)
    if unknown:
        raise ValueError(f"skipped keys must be metric names; not metric names: {unknown}")
    silent = sorted(k for k, v in metrics.items() if v is None and k not in skipped)
    if silent:
        raise ValueError(f"metrics without a value and without a reason in skipped: {silent}")
    unknown = sorted(k for k in metrics if k not in KNOWN_METRICS)
    if unknown:
        raise ValueError(f"unknown metric names (add them to gsbench.results): {unknown}")


def run_results(*, identity: dict, metrics: dict, metric_impl: dict, skipped: dict, per_view: dict,
                view_names: list, frames: dict, frames_skipped: dict, resolution: dict, notes: dict,
                timings: dict, memory: dict, machine: dict, status: str = "done", split: Optional[dict] = None,
                **extra: Any) -> dict:
    """results.json of an evaluated run or a scored mask folder (checked: see `check_skipped`); `split`
    is the run's `gsbench.datasets.splits.split_record` (None where no run was trained)."""
    if status not in STATUSES:
        raise ValueError(f"status must be one of {STATUSES}, got {status!r}")
    check_skipped(metrics, skipped)
    out = {"results_version": RESULTS_VERSION, **_identity(identity)}
    out.update(metric_impl=metric_impl, metrics=metrics, per_view=per_view, view_names=view_names,
               skipped=skipped, notes=notes, frames=frames, frames_skipped=frames_skipped, split=split,
               resolution=resolution, timings=timings, memory=memory, machine=machine, status=status)
    out.update(extra)
    return out


def failed_results(*, identity: dict, reason: str, machine: dict, timings: Optional[dict] = None,
                   metrics: Iterable[str] = (IMAGE_METRICS + REMOVAL_METRICS + ORDERING_METRICS + DEPTH_METRICS
                                              + INPUT_METRICS)
                   ) -> dict:
    """results.json of a cell whose training or evaluation failed: the given metrics null, each with
    `reason` under its own name in skipped, status "failed"."""
    names = list(metrics)
    protocols = identity.get("protocols") or []
    for p in protocols:
        names += [seg_metric(b, p) for b in SEG_BASES[p]]
    mets = {m: None for m in names}
    return run_results(identity=identity, metrics=mets, metric_impl={}, skipped={m: reason for m in names},
                       per_view={}, view_names=[], frames={}, frames_skipped={}, resolution={}, notes={},
                       timings=timings or {"train_s": None, "eval_s": None}, memory={}, machine=machine,
                       status="failed")


IDENTITY_KEYS = ("run_id", "method", "scene", "scene_path", "seed", "study", "grid", "config", "providers",
                 "backend", "protocol", "protocols", "query_mode", "dropped")


REQUIRED_KEYS = ("run_id", "method", "scene", "metrics")
_OBJECTS = ("metrics", "skipped", "grid", "providers", "machine", "timings", "memory", "split")


def check_shape(res: Any, path: Any) -> None:
    """The reader's check of what run_results / failed_results write: an object with the required
    keys, its sections objects (or null), the seed an integer or null; an InputError naming `path`."""
    if not isinstance(res, dict):
        raise InputError(f"{path}: results.json must hold a JSON object, got {type(res).__name__}")
    for key in REQUIRED_KEYS:
        if key not in res:
            raise InputError(f"{path}: missing key '{key}'")
    for key in _OBJECTS:
        if not isinstance(res.get(key) or {}, dict):
            raise InputError(f"{path}: '{key}' must be an object")
    seed = res.get("seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
        raise InputError(f"{path}: 'seed' must be an integer or null, got {seed!r}")


def _identity(identity: dict) -> dict:
    out = {k: identity.get(k) for k in IDENTITY_KEYS}
    out["grid"] = out["grid"] or {}
    out["protocols"] = list(out["protocols"] or [])
    out["dropped"] = out["dropped"] or {}
    out["providers"] = {"depth": None, "masks": None, "features": None, **(out["providers"] or {})}
    extra = sorted(set(identity) - set(IDENTITY_KEYS))
    if extra:
        raise ValueError(f"unknown identity keys: {extra}")
    return out
