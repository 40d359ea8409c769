"""Shared priors: the priors entry each cell will ask for, and computing the shared ones once; then the
same for the feature autoencoder's fit (gsbench.train.semantic_targets), which the cells find in the cache."""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, Callable, Optional

from gsbench.datasets import load_scene
from gsbench.device import resolve_device
from gsbench.errors import InputError
from gsbench.grids.executors import apply_thread_budget
from gsbench.grids.planning import PlannedCell
from gsbench.methods.registry import autoencoder_request
from gsbench.methods.registry import priors_request as method_priors_request
from gsbench.priors import prepare_priors
from gsbench.train.semantic_targets import fit_autoencoder


def priors_request(spec: dict) -> Optional[dict]:
    """The priors entry the cell's method will ask for (the method registry builds the same request
    that train_phases() uses), or None when it needs no priors. Cells with equal requests share one cache entry."""
    return method_priors_request(spec["config"], spec["scene_path"])


def _priors(request: dict):
    apply_thread_budget()
    scene = load_scene(request["scene_path"])
    return prepare_priors(scene, request["priors"], request["view_ids"], tuple(request["size"]),
                          Path(request["priors"]["cache_dir"]), need_depth=request["need_depth"],
                          need_masks=request["need_sem"], need_features=request["need_sem"],
                          per_frame_masks=request["per_frame"], seed=request["seed"], progress=False,
                          device=request.get("device"))


def prepare_priors_job(request: dict) -> dict:
    """Compute one shared priors entry into the cache (run through the executor before the cells)."""
    t0 = time.time()
    try:
        pri = _priors(request)
        return {"ok": True, "seconds": time.time() - t0, "providers": dict(pri.providers)}
    except Exception as e:  # the cells then compute their own priors; the grid says so
        return {"ok": False, "seconds": time.time() - t0, "error": f"{type(e).__name__}: {e}"}


def fit_autoencoder_job(request: dict) -> dict:
    """Fit one shared autoencoder into the cache, from the priors the cells will read (already cached)."""
    t0 = time.time()
    try:
        pri = _priors(request)
        fit_autoencoder(pri.mask_features or {}, request["autoencoder"], request["latent_dim"], request["seed"],
                        Path(request["priors"]["cache_dir"]))
        return {"ok": True, "seconds": time.time() - t0}
    except Exception as e:  # the cells then fit their own; the grid says so
        return {"ok": False, "seconds": time.time() - t0, "error": f"{type(e).__name__}: {e}"}


def _training_device(config: dict) -> Optional[str]:
    try:
        return str(resolve_device(config))
    except InputError:      # the cell fails with this error when it runs
        return None


def _group(todo: list[PlannedCell]) -> tuple[dict, dict]:
    """Pending cells grouped by their priors request and by their autoencoder request."""
    groups: dict[str, list[dict]] = {}
    fits: dict[str, list[dict]] = {}
    for pc in todo:
        req = priors_request(pc.spec())
        if req is None:
            continue
        # prior models run on the cell's training device (not part of what is shared)
        req_dev = dict(req, device=_training_device(pc.config))
        groups.setdefault(json.dumps(req, sort_keys=True, default=str), []).append(req_dev)
        fit = autoencoder_request(pc.config, req)
        if fit is not None:
            key = json.dumps(fit, sort_keys=True, default=str)
            fits.setdefault(key, []).append(dict(fit, device=req_dev["device"]))
    return groups, fits


def _run_shared(job: Callable[[dict], dict], groups: dict, what: str, executor: Any,
                log: Callable[[str], None]) -> dict:
    """Run `job` once for each group of two or more cells; log and return what happened."""
    shared = [reqs[0] for reqs in groups.values() if len(reqs) > 1]
    if not shared:
        return {"groups": 0}
    t0 = time.time()
    out = list(executor.map(job, shared))
    bad = [r["error"] for r in out if not r["ok"]]
    log(f"shared {what}: {len(shared)} for {sum(len(v) for v in groups.values() if len(v) > 1)} cells in "
        f"{time.time() - t0:.1f} s" + (f"; {len(bad)} failed, those cells compute their own: {bad}" if bad else ""))
    return {"groups": len(shared), "seconds": time.time() - t0, "failed": bad}


def shared_priors(todo: list[PlannedCell], executor: Any, log: Callable[[str], None]) -> dict:
    """Compute each priors entry that two or more pending cells share, once, before the cells run
    (so parallel cells never compute the same entry side by side); then each autoencoder fit that two
    or more share, from those priors. Returns the priors' report with the fits' under "autoencoder"."""
    groups, fits = _group(todo)
    report = _run_shared(prepare_priors_job, groups, "priors entries", executor, log)
    report["autoencoder"] = _run_shared(fit_autoencoder_job, fits, "autoencoder fits", executor, log)
    return report


