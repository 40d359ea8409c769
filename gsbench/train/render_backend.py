"""A run's render backend, made ready before any work.

A run's render backend is chosen by gsbench.render's one rule (`resolve_backend`, render/backend_choice.py);
here it is applied to a config and prepared (gsplat's CUDA extension loaded or built) before any work."""
from __future__ import annotations

from typing import Iterable, Optional

import torch

from gsbench.config import setting
from gsbench.device import resolve_device
from gsbench.errors import InputError
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


__all__ = ["resolve_render_backend", "prepare_backend", "prebuild_for"]
