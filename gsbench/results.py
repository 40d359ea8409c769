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
  resolution {frame set: "WxH"}, timings, memory, machine, status, dropped.

Metric names are built from parts (see `METRIC_NAMES`): a segmentation metric is
<base>_<protocol>[_<query mode>][_heldout]; the plain name is the configured query mode on the
`reference` frame set (the frames the references score), `_heldout` the frames not trained on.
"""
from __future__ import annotations

import math
from typing import Any, Iterable, Optional

from gsbench.config_keys import QUERY_MODES

RESULTS_VERSION = 2
STATUSES = ("done", "failed", "nonfinite")
FRAME_SETS = ("reference", "held-out")
FRAME_SET_SUFFIX = {"reference": "", "held-out": "_heldout"}

# ssim / lpips: the 3DGS forms (zero-padded SSIM, LPIPS on [0, 1] inputs) that 3DGS-family papers report;
# ssim_valid / lpips_package: the valid-region SSIM and the LPIPS package's [-1, 1] input convention.
IMAGE_METRICS = ("psnr", "ssim", "lpips", "fps", "ssim_valid", "lpips_package")
SEG_BASES = {"3dovs": ("miou", "mbiou", "pixel_acc", "pixel_acc_labelled"), "lerf": ("miou", "loc_acc")}
MASK_FOLDER_METRICS = ("mbiou_lerf",)
REMOVAL_METRICS = ("removal_residual", "removal_psnr_outside")
DEPTH_METRICS = ("depth_absrel",)
ORDERING_METRICS = ("ordering_adjacent_distance", "ordering_adjacent_mask_iou", "ordering_adjacent_mask_iou_strict",
                    "ordering_adjacent_mask_iou_flow")
TIMING_NAMES = ("train_s", "eval_s", "render_ms")
MEMORY_NAMES = ("peak_rss_mb", "train_peak_rss_mb", "peak_cuda_mb", "train_peak_cuda_mb", "eval_peak_cuda_mb")


def seg_metric(base: str, protocol: str, mode: Optional[str] = None, frame_set: str = "reference") -> str:
    """Name of a segmentation metric, e.g. ("miou", "lerf", "decode", "held-out") -> miou_lerf_decode_heldout."""
    if protocol not in SEG_BASES or base not in SEG_BASES[protocol]:
        raise ValueError(f"no segmentation metric {base!r} for protocol {protocol!r}")
    if mode is not None and mode not in QUERY_MODES:
        raise ValueError(f"query mode must be one of {QUERY_MODES}, got {mode!r}")
    return f"{base}_{protocol}" + (f"_{mode}" if mode else "") + FRAME_SET_SUFFIX[frame_set]


def _seg_names() -> tuple[str, ...]:
    return tuple(seg_metric(b, p, m, f) for p, bases in SEG_BASES.items() for b in bases
                 for m in (None, *QUERY_MODES) for f in FRAME_SETS)


#: every name `metrics` may hold, in report order
METRIC_NAMES: tuple[str, ...] = (IMAGE_METRICS + _seg_names() + MASK_FOLDER_METRICS + REMOVAL_METRICS
                                 + ORDERING_METRICS + DEPTH_METRICS)
#: every quantity a collected row may carry (metrics, timings, memory)
KNOWN_METRICS: frozenset[str] = frozenset(METRIC_NAMES + TIMING_NAMES + MEMORY_NAMES)


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
                timings: dict, memory: dict, machine: dict, status: str = "done", **extra: Any) -> dict:
    """results.json of an evaluated run or a scored mask folder (checked: see `check_skipped`)."""
    if status not in STATUSES:
        raise ValueError(f"status must be one of {STATUSES}, got {status!r}")
    check_skipped(metrics, skipped)
    out = {"results_version": RESULTS_VERSION, **_identity(identity)}
    out.update(metric_impl=metric_impl, metrics=metrics, per_view=per_view, view_names=view_names,
               skipped=skipped, notes=notes, frames=frames, frames_skipped=frames_skipped,
               resolution=resolution, timings=timings, memory=memory, machine=machine, status=status)
    out.update(extra)
    return out


def failed_results(*, identity: dict, reason: str, machine: dict, timings: Optional[dict] = None,
                   metrics: Iterable[str] = IMAGE_METRICS + REMOVAL_METRICS + ORDERING_METRICS + DEPTH_METRICS
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
