"""Run folders: train a method into one (resumable, idempotent).

    run_dir = train_run(config, scene_path, run_dir)      # config from gsbench.config.load_config
    method, config, scene = load_run(run_dir)             # gsbench.evaluation.trained_run: the folder read back

Files (see gsbench/store.py): config.json (resolved: scene, run_id, dropped), env.json, status.json,
train_log.jsonl, checkpoint.pt (trainer state, for resume), model.pt (the trained Method),
train_summary.json (train_s, peak_rss_mb, rss_source, train_peak_cuda_mb on CUDA, iterations,
n_gaussians, providers, dropped, backend, status). The memory figures are the peaks of this run's
training alone (gsbench.environment.PeakMemory), not of the process that ran it.
A folder whose status is "done" is not retrained; one with a checkpoint resumes from it.
Only one process writes a run folder at a time (gsbench.runlock: a second one exits with the holder).
"""
from __future__ import annotations

import logging
import os
import time
from pathlib import Path

import numpy as np
import torch

from gsbench import rundir
from gsbench.config import run_config, run_id, setting
from gsbench.datasets import load_scene, scene_fingerprint
from gsbench.device import resolve_device
from gsbench.environment import PeakMemory, env_info
from gsbench.errors import InputError, NonFiniteError, Terminated, interrupted
from gsbench.methods.registry import get_method, resolve_for_scene
from gsbench.priors.depth import asks_depth_rule, settle_depth_rule
from gsbench.render.threads import numba_threading_layer
from gsbench.runlock import RunLock
from gsbench.runs.training import train_method
from gsbench.store import read_json, read_jsonl, write_json_atomic

log = logging.getLogger(__name__)


def _load_scene(scene_path):
    return load_scene(scene_path)


def _fingerprint(scene_path) -> str:
    return scene_fingerprint(scene_path)


def _device(cfg: dict) -> str:
    """The device training uses, for the memory counters (gsbench.device.resolve_device). A config
    it refuses gets "cpu" here: training raises the same error next and records it in status.json."""
    try:
        return str(resolve_device(cfg))
    except InputError:
        return "cpu"


def dropped_line(dropped: dict) -> str:
    """What the resolver left out, on one line: parts sharing a reason are listed before it once."""
    by_reason: dict[str, list[str]] = {}
    for part, why in dropped.items():
        by_reason.setdefault(str(why), []).append(str(part))
    return "dropped (not used by this run): " + "; ".join(f"{', '.join(parts)} ({why})"
                                                       for why, parts in by_reason.items())


def train_run(config: dict, scene_path: str | Path, run_dir: Path, progress: bool = True) -> Path:
    """Resolve `config` for the scene, train (or resume) and write the run folder; returns run_dir.

    Holds the folder's writer lock (gsbench.runlock) throughout: a second writer is refused."""
    run_dir = Path(run_dir)
    with RunLock(run_dir):
        return _train_run(config, Path(scene_path), run_dir, progress)


def _train_run(config: dict, scene_path: Path, run_dir: Path, progress: bool) -> Path:
    fp = _fingerprint(scene_path)
    scene = _load_scene(scene_path) if asks_depth_rule(config) else None
    if scene is not None:   # `auto` is settled on the scene before the id is taken
        config = settle_depth_rule(config, scene)
    rid = run_id(config, fp)
    st = rundir.read_status(run_dir)
    if (run_dir / rundir.CONFIG).exists():
        old = run_config(read_json(run_dir / rundir.CONFIG), run_dir / rundir.CONFIG)
        if old.get("run_id") != rid:
            raise InputError(f"{run_dir}: the folder holds run {old.get('run_id')} (another config or scene); "
                             f"use a new --out folder")
    if st is not None and st.get("state") == "done":
        if progress:
            log.warning("gsbench train: %s is already done (run %s); not retrained", run_dir, rid)
        return run_dir
    scene = scene or _load_scene(scene_path)
    cfg, dropped = resolve_for_scene(config, scene)
    cfg["scene"] = {"path": str(scene_path.resolve()), "name": scene.name, "fingerprint": fp,
                    "points": scene.points_digest()}   # the initialisation: outside the fingerprint
    cfg["run_id"] = rid
    if dropped:
        log.warning("%s", dropped_line(dropped))
    run_dir.mkdir(parents=True, exist_ok=True)
    seed = int(setting(cfg, "seed"))
    torch.manual_seed(seed)
    np.random.seed(seed)
    threads_before = torch.get_num_threads()
    # a grid executor sets GSBENCH_THREADS (cores // jobs) so parallel cells do not oversubscribe
    torch.set_num_threads(int(os.environ.get("GSBENCH_THREADS") or 0) or max(1, os.cpu_count() or 1))
    write_json_atomic(run_dir / rundir.CONFIG, cfg)
    write_json_atomic(run_dir / rundir.ENV, env_info())
    prev_s = float((st or {}).get("train_s_so_far") or 0.0)
    rundir.write_status(run_dir, "running", "", train_s_so_far=prev_s)
    method = get_method(cfg["method"])()
    t0 = time.perf_counter()
    memory = PeakMemory(_device(cfg)).start()
    try:
        train_method(method, scene, run_dir, cfg, progress=progress)
    except NonFiniteError as e:
        _finish(run_dir, method, cfg, "nonfinite", str(e), prev_s + time.perf_counter() - t0, memory.read())
        raise
    except (KeyboardInterrupt, Exception) as e:
        so_far = prev_s + time.perf_counter() - t0
        if not interrupted(e):
            rundir.write_status(run_dir, "failed", f"{type(e).__name__}: {e}", train_s_so_far=so_far)
            raise
        how = "terminated (SIGTERM)" if isinstance(e, Terminated) else "interrupted"
        rundir.write_status(run_dir, "interrupted", f"{how}; re-run to resume from the last checkpoint",
                            train_s_so_far=so_far)
        if isinstance(e, KeyboardInterrupt):
            raise
        raise KeyboardInterrupt from e      # Ctrl-C during a numba kernel (errors.interrupted)
    finally:
        torch.set_num_threads(threads_before)
    train_s = prev_s + time.perf_counter() - t0
    peaks = memory.read()
    method.save(run_dir / rundir.MODEL)
    _finish(run_dir, method, cfg, "done", "", train_s, peaks)
    return run_dir


def _finish(run_dir: Path, method, cfg: dict, state: str, message: str, train_s: float, peaks: dict) -> None:
    log = read_jsonl(run_dir / rundir.TRAIN_LOG)
    steps = [int(r["step"]) for r in log if "step" in r]
    last_eval = next((r["eval"] for r in reversed(log) if "eval" in r), None)
    n = method.field.num if getattr(method, "field", None) is not None else None
    # the identity of the config as written (after the resolver): `gsbench eval` recomputes it from
    # config.json and refuses an edited one (gsbench.evaluation.trained_run.check_identity)
    fp = (cfg.get("scene") or {}).get("fingerprint")
    summary = {"run_id": cfg.get("run_id"), "resolved_config_id": run_id(cfg, fp) if isinstance(fp, str) else None,
               "method": cfg["method"], "status": state, "message": message,
               "train_s": train_s, "peak_rss_mb": peaks["peak_rss_mb"], "rss_source": peaks["rss_source"],
               "iterations": max(steps) if steps else 0, "n_gaussians": n,
               "providers": method.provider_ids(), "dropped": cfg.get("dropped", {}), "backend": method.backend,
               "last_eval": last_eval, "info": getattr(method, "info", {})}
    if method.backend == "cpu":     # speed only: the kernels give the same bits on every layer
        summary["numba_threading_layer"] = numba_threading_layer()
    if "peak_cuda_mb" in peaks:
        summary["train_peak_cuda_mb"] = peaks["peak_cuda_mb"]
    write_json_atomic(run_dir / rundir.TRAIN_SUMMARY, summary)
    rundir.write_status(run_dir, state, message, train_s_so_far=train_s)
