"""The render backend for a training device (auto | torch | cpu | gsplat), checked up front, and gsplat's
CUDA extension built before any work. The device rule itself is gsbench/device.py."""
from __future__ import annotations

import logging
from typing import Iterable

import torch

from gsbench.config import setting
from gsbench.device import resolve_device
from gsbench.errors import InputError
from gsbench.render.gsplat_ext import NEEDS_BUILD, build_gsplat_extension, gsplat_status

log = logging.getLogger(__name__)


def gsplat_available() -> bool:
    """gsplat imports AND can render: its CUDA extension is shipped, cached, or buildable (nvcc found)."""
    return gsplat_status().usable


def resolve_backend_for(backend: str, device: torch.device) -> str:
    """The concrete render backend for a device: auto -> gsplat on CUDA (torch, with one warning, when
    gsplat cannot render here), cpu on the CPU. An explicit choice that cannot run there is an error."""
    backend = str(backend or "auto")
    if device.type == "cuda":
        if backend == "auto":
            if gsplat_available():
                return "gsplat"
            log.warning("backend auto on %s: gsplat cannot render here (%s); rendering with the torch backend "
                        "(slow)", device, gsplat_status().detail)
            return "torch"
        if backend == "cpu":
            raise InputError(f"backend=cpu renders on the CPU only but train.device is {device}; "
                             f"use backend auto, gsplat or torch (or train.device=auto or cpu)")
        if backend == "gsplat" and not gsplat_available():
            raise InputError(f"backend=gsplat: gsplat cannot render here: {gsplat_status().detail}")
        return backend
    if backend == "gsplat":
        raise InputError("backend=gsplat needs train.device=cuda (gsplat renders CUDA tensors only)")
    if backend == "auto":
        backend = "cpu"
    if backend == "cpu":
        try:
            import gsbench.render.cpu_backend  # lazy: optional (numba probe)  # noqa: F401
        except ImportError as e:
            raise InputError(f"render backend 'cpu' is not available in this build ({e}); "
                             f"use --set backend=torch") from None
    elif backend != "torch":
        raise InputError(f"unknown render backend {backend!r}; choose auto, torch, cpu or gsplat")
    return backend


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
            if resolve_backend_for(setting(cfg, "backend"), resolve_device(cfg)) == "gsplat":
                build_gsplat_extension()
                return True
        except InputError:      # the cell fails with its own error line when it runs
            continue
    return False


__all__ = ["resolve_backend_for", "gsplat_available", "prepare_backend", "prebuild_for"]
