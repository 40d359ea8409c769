"""Which render backend renders on a device: the one rule of gsbench (auto | torch | cpu | gsplat).

    resolve_backend("auto", cuda)  -> "gsplat" when gsplat can render here, else "torch" with one warning
    resolve_backend("auto", cpu)   -> "cpu"
    resolve_backend(name, device)  -> name, when that backend can run there; else an InputError (cpu on
                                      CUDA, gsplat off CUDA or without a usable gsplat, cpu without
                                      numba, an unknown name)

The methods resolve a run's backend with it once, up front (`gsbench/train/render_backend.py`
`resolve_render_backend`, `Method.load`), and so do grids (gsplat's one-time build) and `gsbench
doctor`; `render()` resolves `auto` with it and trusts a concrete name, so no frame re-reads gsplat's
files. Which device `train.device: auto` picks is gsbench/device.py.
"""
from __future__ import annotations

import logging

import torch

from gsbench.config_keys import BACKENDS as BACKEND_CHOICES
from gsbench.errors import InputError
from gsbench.render.gsplat_ext import gsplat_status

log = logging.getLogger(__name__)

BACKENDS = tuple(b for b in BACKEND_CHOICES if b != "auto")   # the concrete backends; `auto` resolves to one


def gsplat_available() -> bool:
    """gsplat imports AND can render: its CUDA extension is shipped, cached, or buildable (nvcc found)."""
    return gsplat_status().usable


def resolve_backend(backend: str, device: torch.device) -> str:
    """The concrete render backend for a device: auto -> gsplat on CUDA (torch, with one warning, when
    gsplat cannot render here), cpu on the CPU. An explicit choice that cannot run there is an error."""
    backend = str(backend or "auto")
    if backend != "auto" and backend not in BACKENDS:
        raise InputError(f"unknown render backend {backend!r}; choose one of auto, {', '.join(BACKENDS)}")
    device = torch.device(device)
    if device.type == "cuda":
        return _on_cuda(backend, device)
    return _on_cpu(backend)


def _on_cuda(backend: str, device: torch.device) -> str:
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


def _on_cpu(backend: str) -> str:
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
    return backend


__all__ = ["BACKENDS", "gsplat_available", "resolve_backend"]
