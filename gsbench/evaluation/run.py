"""A trained run -> results.json: reconstruction metrics on the held-out views, FPS, segmentation
per protocol / frame set / query mode, object removal, and the run's ordering statistics."""
from __future__ import annotations

import copy
import logging
import os
import time
from pathlib import Path
from typing import Any, Optional

from gsbench import rundir
from gsbench.config import setting
from gsbench.datasets.splits import split_record
from gsbench.environment import PeakMemory, env_info
from gsbench.errors import InputError
from gsbench.evaluation.trained_run import load_run
from gsbench.metric_table import ORDERING_METRICS
from gsbench.metrics import ordering as MO
from gsbench.results import run_results
from gsbench.runlock import RunLock
from gsbench.store import read_json, write_json_atomic

from .block import Block
from .depth import depth_metrics
from .frames import frame_sets, train_camera, view_name
from .image import fps, image_metrics
from .previews import preview_keys, save_previews
from .protocol_registry import get_protocol
from .removal import removal
from .segmentation import query_mode, requested_forks, resolve_protocols, segmentation, segmentation_frames

log = logging.getLogger(__name__)


def _ordering(run_dir: Path) -> Block:
    out = Block()
    summary = rundir.read_optional(run_dir / rundir.TRAIN_SUMMARY)
    stats = (summary.get("info") or {}).get("priors_stats") or summary.get("priors_stats") or {}
    impls = {"ordering_adjacent_distance": MO.ORDERING_DISTANCE_IMPL,
             "ordering_adjacent_mask_iou": MO.ORDERING_MASK_IOU_IMPL,
             "ordering_adjacent_mask_iou_strict": MO.ORDERING_MASK_IOU_STRICT_IMPL,
             "ordering_adjacent_mask_iou_flow": MO.ORDERING_MASK_IOU_FLOW_IMPL}
    for k in ORDERING_METRICS:
        out.put(k, stats.get(k), impls.get(k),
                "not in the run's priors stats (no masks/ordering prior for this method or scene)")
    return out


EDGE_IMPL = "ds-edges/canny-minmax8-dilated/share-of-pixels/v1"


def _edges(run_dir: Path) -> Block:
    """ds_edge_fraction: the mean share of pixels the L_ds edge map E_d marked in training (train summary)."""
    out = Block()
    info = rundir.read_optional(run_dir / rundir.TRAIN_SUMMARY).get("info") or {}
    share = info.get("edge_fraction")
    out.put("ds_edge_fraction", None if share is None else float(share), EDGE_IMPL,
            "no L_ds edge map in the run's train summary (a method without L_ds, or L_ds off)")
    return out


def _unscored(scene, fs, protocols: list[str], sets: dict) -> dict:
    """Labelled frames that no frame set scores, with the reason (never dropped silently)."""
    out = {}
    for p, ids in fs.labelled.items():
        if p not in protocols:
            for i in ids:
                out[f"{p}/{view_name(scene, i)}"] = f"protocol {p} not evaluated (--protocol)"
            continue
        scored = {i for v in sets[p].values() for i in v}
        for i in ids:
            if i not in scored:
                raise RuntimeError(f"labelled {p} frame {view_name(scene, i)} is in no frame set")
    return out


def _memory(summary: dict, eval_peaks: dict) -> dict:
    """This evaluation's peaks (counters reset at its start) beside the training peaks of train_summary.json."""
    memory = {"peak_rss_mb": eval_peaks["peak_rss_mb"], "rss_source": eval_peaks["rss_source"]}
    if "peak_cuda_mb" in eval_peaks:
        memory["eval_peak_cuda_mb"] = eval_peaks["peak_cuda_mb"]
    if "peak_rss_mb" in summary:
        memory["train_peak_rss_mb"] = summary["peak_rss_mb"]
        memory["train_rss_source"] = summary.get("rss_source")
    if "train_peak_cuda_mb" in summary:
        memory["train_peak_cuda_mb"] = summary["train_peak_cuda_mb"]
    return memory


def requested_protocol(protocol: Optional[str], config: dict) -> str:
    """The protocol argument when given (protocol and fork names, comma-separated), else the run config's
    eval.protocol (default auto)."""
    return protocol or setting(config, "eval.protocol") or "auto"


def evaluate_run(run_dir: str | os.PathLike, protocol: Optional[str] = None, progress: bool = True) -> dict:
    """Evaluate a trained run and write run_dir/results.json (schema: gsbench.results), holding the
    run folder's writer lock. protocol None = the run config's eval.protocol; a fork name (e.g.
    "3dovs-threshold") scores its protocol under that fork, and results.json records each protocol's fork
    under `forks`."""
    with RunLock(Path(run_dir), command="gsbench eval"):
        return _evaluate_run(Path(run_dir), protocol, progress)


def _evaluate_run(run_dir: Path, protocol: Optional[str], progress: bool) -> dict:
    import torch

    t_start = time.time()
    method, config, scene = load_run(run_dir)
    peaks = PeakMemory(getattr(method, "device", None)).start()
    protocol = requested_protocol(protocol, config)
    mode = query_mode(config)
    fs = frame_sets(scene, config)
    max_width = setting(config, "train.max_width")
    rec_cams = [train_camera(scene.cameras[i], max_width) for i in fs.reconstruction]
    protocols, pskip = resolve_protocols(scene, protocol)
    forks = requested_forks(protocol, protocols)
    sets = {p: fs.protocol_sets(p) for p in protocols}
    out = Block()
    with torch.no_grad():
        out.merge(image_metrics(method, scene, fs.reconstruction, rec_cams, config, progress))
        time_cams = rec_cams or [train_camera(scene.cameras[i], max_width) for i in fs.trained[:8]]
        out.merge(fps(method, time_cams, config))
        scored = segmentation_frames(method, scene, protocols, sets, config, forks=forks)
        out.merge(segmentation(method, scene, protocols, sets, config, frames=scored, forks=forks))
        shown = preview_keys(protocols, sets, config, mode)
        scored = {k: v for k, v in scored.items() if k in shown}      # what the previews show, no more
        out.merge(removal(method, scene, fs.reconstruction, rec_cams, config))
        out.merge(depth_metrics(method, scene, fs.reconstruction, rec_cams))
    out.merge(_ordering(run_dir))
    out.merge(_edges(run_dir))
    for p, why in pskip.items():
        out.skip(get_protocol(p).plain_names(), why)
    frames_skipped = _unscored(scene, fs, protocols, sets)

    summary = rundir.read_optional(run_dir / rundir.TRAIN_SUMMARY)
    train_status = rundir.read_optional(run_dir / rundir.STATUS)
    out.timings["train_s"] = summary.get("train_s", summary.get("wall_s"))
    out.timings["eval_s"] = time.time() - t_start
    providers = {}
    try:
        providers = dict(method.provider_ids() or {})
    except AttributeError:
        out.notes["providers"] = "method has no provider_ids()"
    state = train_status.get("state", "done")
    identity = {
        "run_id": config.get("run_id", run_dir.name), "method": config.get("method"),
        "scene": scene.name or Path(scene.path).name, "scene_path": str(scene.path), "seed": config.get("seed"),
        "study": config.get("study") or _cell_field(run_dir, "study"), "grid": config.get("grid") or {},
        "config": config, "providers": providers,
        "backend": getattr(method, "backend", None) or config.get("backend"),
        "protocol": protocols[0] if protocols else None, "protocols": protocols, "query_mode": mode,
        "dropped": config.get("dropped", {}),
    }
    with torch.no_grad():
        pv = {k: identity[k] for k in ("run_id", "method", "scene", "providers", "backend")}
        save_previews(run_dir, method, scene, protocols, sets, fs.reconstruction, rec_cams, config, mode, pv, scored,
                      forks)
    results = run_results(identity=identity, metrics=out.metrics, metric_impl=out.metric_impl,
                          skipped=out.skipped, per_view=out.per_view,
                          view_names=out.frames.get("reconstruction", []), frames=out.frames,
                          frames_skipped=frames_skipped, split=split_record(scene, config),
                          resolution=out.resolution, notes=out.notes,
                          timings=out.timings, memory=_memory(summary, peaks.read()), machine=env_info(),
                          status=state if state in ("done", "failed", "nonfinite") else "done",
                          train_device=(summary.get("info") or {}).get("device"),
                          eval_device=str(getattr(method, "device", "cpu")),
                          budget=(summary.get("info") or {}).get("budget"),
                          forks={p: f for p, f in forks.items() if f})
    write_json_atomic(run_dir / rundir.RESULTS, results)
    return results


def _cell_field(run_dir: Path, key: str) -> Any:
    p = run_dir / rundir.CELL
    cell = read_json(p) if p.exists() else None
    if cell is not None and not isinstance(cell, dict):
        raise InputError(f"{p}: expected a JSON object, got {type(cell).__name__}")
    return cell.get(key) if cell is not None else None


def segmentation_metrics(method, scene, view_ids: list[int], cams: list, config: dict) -> tuple[dict, dict]:
    """(metrics, skipped) of the scene's segmentation protocols that render frames on the given views at
    the training resolution, in the configured query mode: the same code as `evaluate_run`, for the trainer's
    periodic evaluation. `cams` must be those views at the training resolution."""
    import torch
    mode = query_mode(config)
    cfg = copy.deepcopy(config)
    cfg.setdefault("eval", {})["resolution"] = "train"
    protocols, pskip = resolve_protocols(scene, "auto")
    protocols = [p for p in protocols if get_protocol(p).renders_frames]    # what training logs score
    pskip = {p: why for p, why in pskip.items() if get_protocol(p).renders_frames}
    ids = set(view_ids)
    sets = {}
    fs = frame_sets(scene, cfg)
    for p in protocols:
        sets[p] = {"held-out": [i for i in fs.labelled.get(p, []) if i in ids]}
    with torch.no_grad():
        out = segmentation(method, scene, protocols, sets, cfg, modes=(mode,))
    metrics, skipped = {}, {}
    for p in protocols:
        proto = get_protocol(p)
        for b in proto.metrics:
            k = proto.metric_name(b, None, "held-out")
            metrics[proto.metric_name(b)] = out.metrics.get(k)
            if k in out.skipped:
                skipped[proto.metric_name(b)] = out.skipped[k]
    for p, why in pskip.items():
        for n in get_protocol(p).plain_names():
            metrics[n] = None
            skipped[n] = why
    return metrics, skipped

