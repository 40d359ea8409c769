"""Glue shared by the methods: which inputs a resolved config uses, priors, render backend, a phase's trainer.

A run's render backend is chosen by gsbench.render's one rule (`resolve_backend`, render/backend_choice.py);
here it is applied to a config and prepared (gsplat's CUDA extension loaded or built) before any work."""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Iterable, Optional

import torch

from gsbench import rundir
from gsbench.config import setting
from gsbench.device import resolve_device
from gsbench.errors import InputError
from gsbench.gaussians import GaussianField
from gsbench.methods.registry import build_priors_request, uses
from gsbench.methods.trainer import LossResult, Trainer, TrainViews
from gsbench.priors import prepare_priors
from gsbench.render import resolve_backend
from gsbench.render.gsplat_ext import NEEDS_BUILD, build_gsplat_extension, gsplat_status


def resolve_render_backend(config: dict, device: Optional[torch.device] = None) -> str:
    """The concrete backend id of the config's `backend` for the training device (gsbench.render's rule:
    `auto` -> gsplat on CUDA, cpu on the CPU); checked now, not mid-run. `device` defaults to the
    config's `train.device`."""
    dev = resolve_device(config) if device is None else torch.device(device)
    return resolve_backend(setting(config, "backend"), dev)


def prepare_backend(backend: str) -> None:
    """Before any work: load gsplat's CUDA extension when the run renders with gsplat (compiling it,
    announced, when this machine has no build yet), so the first render neither compiles silently
    nor dies on a missing extension."""
    if backend == "gsplat":
        build_gsplat_extension()


def prebuild_for(configs: Iterable[dict]) -> bool:
    """Build gsplat's extension once, here, when any of `configs` will render with gsplat on this
    machine and no build exists yet: a grid calls it before its workers start, so they load the
    build instead of compiling at once in the same folder. Returns whether it built."""
    if gsplat_status().state != NEEDS_BUILD:
        return False
    for cfg in configs:
        try:
            if resolve_render_backend(cfg) == "gsplat":
                build_gsplat_extension()
                return True
        except InputError:      # the cell fails with its own error line when it runs
            continue
    return False


def cache_dir_for(config: dict, run_dir: Path) -> Path:
    c = config["priors"].get("cache_dir")
    return Path(c) if c else Path(run_dir).resolve().parent / rundir.CACHE_DIRNAME


def fit_priors(scene, config: dict, run_dir: Path, *, progress: bool):
    """The priors of a method's train_phases(): computed from the registry's priors request, the same dict a grid builds
    to share priors between cells, so the two cannot ask for different cache entries."""
    req = build_priors_request(config, scene)
    if req is None:
        raise InputError(f"{scene.path}: the scene has no training views")
    return prepare_priors(scene, req["priors"], req["view_ids"], tuple(req["size"]), cache_dir_for(config, run_dir),
                          need_depth=req["need_depth"], need_masks=req["need_sem"], need_features=req["need_sem"],
                          per_frame_masks=req["per_frame"], seed=req["seed"], progress=progress,
                          device=str(resolve_device(config)))


def make_trainer(config: dict, views: TrainViews, scene, field0: GaussianField, run_dir: Path,
                 loss_fn: Callable, *, phase: str, backend: str, iterations: Optional[int] = None,
                 trainable: Optional[set] = None, densify: bool = True,
                 extra_state: Optional[Callable[[], dict]] = None) -> Trainer:
    """One optimisation phase with the shared 3DGS recipe and the method's loss, on the views' device:
    what a method yields to the harness's loop (gsbench.runs.training) from `train_phases`."""
    dev = next(iter(views.images.values())).device if views.images else torch.device("cpu")
    return Trainer(config, views, float(scene.extent or 1.0), field0, run_dir, loss_fn, phase=phase,
                   iterations=iterations, trainable=trainable, densify=densify, backend=backend,
                   seed=int(config["seed"]), extra_state=extra_state, device=dev)


__all__ = ["uses", "resolve_render_backend", "prepare_backend", "prebuild_for", "fit_priors", "make_trainer",
           "LossResult", "cache_dir_for"]
