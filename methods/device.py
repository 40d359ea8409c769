"""Where training runs: `train.device` (auto | cpu | cuda | cuda:N) resolved once, checked up front.

Everything a step touches (field, Adam state, images, priors, autoencoder, losses, densification
statistics) is created on or moved to this device by the methods, so a step never copies to the host.
"""
from __future__ import annotations

import logging
from typing import Iterable

import torch

from gsbench.errors import InputError
from gsbench.render.gsplat_ext import NEEDS_BUILD, build_gsplat_extension, gsplat_status

log = logging.getLogger(__name__)
CPU_ONLY_BACKENDS = ("cpu",)    # backends that render CPU tensors only: `auto` devices follow them


def resolve_device(config: dict) -> torch.device:
    """The torch device of `train.device`. 'auto' = the CPU when the config's backend renders on the
    CPU only (backend: cpu, as the CPU presets pin it), else cuda:0 when CUDA is available, else the CPU.

    Asking for CUDA on a machine without it is a one-line InputError (no silent CPU fallback)."""
    want = str((config.get("train") or {}).get("device", "auto") or "auto").strip().lower()
    if want == "auto":
        if str(config.get("backend") or "auto") in CPU_ONLY_BACKENDS:
            return torch.device("cpu")
        return torch.device("cuda", 0) if torch.cuda.is_available() else torch.device("cpu")
    if want == "cpu":
        return torch.device("cpu")
    if want == "cuda" or want.startswith("cuda:"):
        idx = 0
        if want != "cuda":
            try:
                idx = int(want.split(":", 1)[1])
            except ValueError:
                raise InputError(f"train.device: {want!r} is not auto, cpu, cuda or cuda:N") from None
        if not torch.cuda.is_available():
            raise InputError(f"train.device={want}: CUDA is not available on this machine "
                             f"(torch {torch.__version__}, built with CUDA {torch.version.cuda}); "
                             f"use train.device=cpu or auto")
        n = torch.cuda.device_count()
        if idx < 0 or idx >= n:
            raise InputError(f"train.device={want}: this machine has {n} CUDA device(s) (cuda:0..cuda:{n - 1})")
        return torch.device("cuda", idx)
    raise InputError(f"train.device: {want!r} is not auto, cpu, cuda or cuda:N")


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
            if resolve_backend_for(cfg.get("backend", "auto"), resolve_device(cfg)) == "gsplat":
                build_gsplat_extension()
                return True
        except InputError:      # the cell fails with its own error line when it runs
            continue
    return False


__all__ = ["resolve_device", "resolve_backend_for", "gsplat_available", "prepare_backend", "prebuild_for",
           "CPU_ONLY_BACKENDS"]
