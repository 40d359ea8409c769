"""Glue shared by the methods: which inputs a resolved config uses, priors, render backend, trainer call."""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Optional

import torch

from gsbench.errors import InputError
from gsbench.gaussians import GaussianField
from gsbench.methods.device import resolve_backend_for, resolve_device
from gsbench.methods.registry import build_priors_request, uses
from gsbench.methods.trainer import LossResult, Trainer, TrainViews, periodic_eval
from gsbench.priors import prepare_priors


def resolve_render_backend(config: dict, device: Optional[torch.device] = None) -> str:
    """The concrete backend id for the training device (`auto` -> gsplat on CUDA, cpu on the CPU);
    checked importable now, not mid-run. `device` defaults to the config's `train.device`."""
    dev = resolve_device(config) if device is None else torch.device(device)
    return resolve_backend_for(config.get("backend", "auto"), dev)


def cache_dir_for(config: dict, run_dir: Path) -> Path:
    c = config["priors"].get("cache_dir")
    return Path(c) if c else Path(run_dir).resolve().parent / ".gsbench_cache"


def fit_priors(scene, config: dict, run_dir: Path, *, progress: bool):
    """The priors of fit(): computed from the registry's priors request, the same dict a grid builds
    to share priors between cells, so the two cannot ask for different cache entries."""
    req = build_priors_request(config, scene)
    if req is None:
        raise InputError(f"{scene.path}: the scene has no training views")
    return prepare_priors(scene, req["priors"], req["view_ids"], tuple(req["size"]), cache_dir_for(config, run_dir),
                          need_depth=req["need_depth"], need_masks=req["need_sem"], need_features=req["need_sem"],
                          per_frame_masks=req["per_frame"], seed=req["seed"], progress=progress,
                          device=str(resolve_device(config)))


def semantic_eval(method, scene, views: TrainViews, config: dict) -> Optional[Callable[[GaussianField], dict]]:
    """Periodic segmentation mIoU of a semantic method on the eval views (training resolution), with
    gsbench.evaluation's code in the configured query mode: {"miou_3dovs": .., "miou_lerf": ..} for the
    protocols the scene supports. Returns {} while the field has no latents or the method no
    autoencoder yet (e.g. twostage's rgb phase); None when the scene has no segmentation GT at all.
    The scorer is `method.segmentation_scorer`, handed in by the harness (gsbench.runs); without one
    each entry says so ("miou_skipped")."""
    if method is None or not views.eval_cameras or not (scene.has_semantics or scene.has_labels):
        return None
    import copy
    scorer = method.segmentation_scorer
    ids = sorted(views.eval_cameras)
    cams = [views.eval_cameras[i] for i in ids]

    def _sem(fld: GaussianField) -> dict:
        probe = copy.copy(method)
        probe.field = fld
        if not probe.has_semantics:   # e.g. no latents yet, or no autoencoder yet (twostage's rgb phase)
            return {}
        if scorer is None:
            return {"miou_skipped": "no segmentation scorer: fit() was not called through gsbench.runs.train_run"}
        try:   # build (and cache) the text encoder once, on the real method
            method.feature_provider()
        except (InputError, ImportError, OSError) as e:
            # e.g. CLIP weights missing while the priors came from the cache: training goes on, and
            # the log says why this entry has no mIoU (gsbench eval will raise the same error)
            return {"miou_skipped": f"text encoder unavailable: {type(e).__name__}: {e}"}
        m = copy.copy(method)
        m.field = fld
        metrics, skipped = scorer(m, scene, ids, cams, config)
        out = {k: float(metrics[k]) for k in ("miou_3dovs", "miou_lerf") if metrics.get(k) is not None}
        if out:
            out["query_mode"] = (config.get("query") or {}).get("mode", "encode")
        elif skipped:   # e.g. the eval views carry no segmentation GT
            out["miou_skipped"] = "; ".join(f"{k}: {v}" for k, v in sorted(skipped.items()))
        return out

    return _sem


def run_trainer(config: dict, views: TrainViews, scene, field0: GaussianField, run_dir: Path,
                loss_fn: Callable, *, phase: str, backend: str, progress: bool, resume: Optional[dict],
                iterations: Optional[int] = None, trainable: Optional[set] = None, densify: bool = True,
                extra_state: Optional[Callable[[], dict]] = None, method=None) -> GaussianField:
    """Run one trainer phase, resuming when `resume` is a checkpoint of that phase. With `method` (a
    semantic Method whose autoencoder is set), the periodic evaluation also logs segmentation mIoU."""
    dev = next(iter(views.images.values())).device if views.images else torch.device("cpu")
    tr = Trainer(config, views, float(scene.extent or 1.0), field0, run_dir, loss_fn, phase=phase,
                 iterations=iterations, trainable=trainable, densify=densify, backend=backend,
                 seed=int(config["seed"]), extra_state=extra_state, device=dev)
    tr.eval_fn = periodic_eval(views, backend, tr.background, extra=semantic_eval(method, scene, views, config))
    st = resume if (resume is not None and resume.get("phase") == phase) else None
    return tr.run(progress=progress, resume_state=st)


__all__ = ["uses", "resolve_render_backend", "fit_priors", "run_trainer", "semantic_eval", "LossResult",
           "cache_dir_for"]
