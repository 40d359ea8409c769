"""Shared priors: the priors entry each cell will ask for, and computing the shared ones once."""
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
from gsbench.methods.registry import priors_request as method_priors_request
from gsbench.priors import prepare_priors


def priors_request(spec: dict) -> Optional[dict]:
    """The priors entry the cell's method will ask for (the method registry builds the same request
    that train_phases() uses), or None when it needs no priors. Cells with equal requests share one cache entry."""
    return method_priors_request(spec["config"], spec["scene_path"])


def prepare_priors_job(request: dict) -> dict:
    """Compute one shared priors entry into the cache (run through the executor before the cells)."""
    t0 = time.time()
    try:
        apply_thread_budget()
        scene = load_scene(request["scene_path"])
        pri = prepare_priors(scene, request["priors"], request["view_ids"], tuple(request["size"]),
                             Path(request["priors"]["cache_dir"]), need_depth=request["need_depth"],
                             need_masks=request["need_sem"], need_features=request["need_sem"],
                             per_frame_masks=request["per_frame"], seed=request["seed"], progress=False,
                             device=request.get("device"))
        return {"ok": True, "seconds": time.time() - t0, "providers": dict(pri.providers)}
    except Exception as e:  # the cells then compute their own priors; the grid says so
        return {"ok": False, "seconds": time.time() - t0, "error": f"{type(e).__name__}: {e}"}


def _training_device(config: dict) -> Optional[str]:
    try:
        return str(resolve_device(config))
    except InputError:      # the cell fails with this error when it runs
        return None


def shared_priors(todo: list[PlannedCell], executor: Any, log: Callable[[str], None]) -> dict:
    """Compute each priors entry that two or more pending cells share, once, before the cells run
    (so parallel cells never compute the same entry side by side)."""
    groups: dict[str, list[dict]] = {}
    for pc in todo:
        req = priors_request(pc.spec())
        if req is not None:   # prior models run on the cell's training device (not part of what is shared)
            groups.setdefault(json.dumps(req, sort_keys=True, default=str), []).append(
                dict(req, device=_training_device(pc.config)))
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


