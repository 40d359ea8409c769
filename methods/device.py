"""Where training runs: `train.device` (auto | cpu | cuda | cuda:N) resolved once, checked up front.

Everything a step touches (field, Adam state, images, priors, autoencoder, losses, densification
statistics) is created on or moved to this device by the methods, so a step never copies to the host.
"""
from __future__ import annotations

import logging

import torch

from gsbench.errors import InputError

log = logging.getLogger(__name__)


def resolve_device(config: dict) -> torch.device:
    """The torch device of `train.device`; 'auto' = cuda:0 when CUDA is available, else cpu.

    Asking for CUDA on a machine without it is a one-line InputError (no silent CPU fallback)."""
    want = str((config.get("train") or {}).get("device", "auto") or "auto").strip().lower()
    if want == "auto":
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
    try:
        import gsplat  # noqa: F401
    except Exception:   # noqa: BLE001 - a broken CUDA build raises more than ImportError
        return False
    return True


def resolve_backend_for(backend: str, device: torch.device) -> str:
    """The concrete render backend for a device: auto -> gsplat on CUDA (torch, with one warning, when
    gsplat cannot be imported), cpu on the CPU. An explicit choice that cannot run there is an error."""
    backend = str(backend or "auto")
    if device.type == "cuda":
        if backend == "auto":
            if gsplat_available():
                return "gsplat"
            log.warning("backend auto on %s: gsplat is not importable, rendering with the torch backend (slow)", device)
            return "torch"
        if backend == "cpu":
            raise InputError(f"backend=cpu renders on the CPU only but train.device is {device}; "
                             f"use backend auto, gsplat or torch")
        if backend == "gsplat" and not gsplat_available():
            raise InputError("backend=gsplat: the gsplat package is not importable (pip install 'gsbench[cuda]')")
        return backend
    if backend == "gsplat":
        raise InputError("backend=gsplat needs train.device=cuda (gsplat renders CUDA tensors only)")
    if backend == "auto":
        backend = "cpu"
    if backend == "cpu":
        try:
            import gsbench.render.cpu_backend  # noqa: F401
        except ImportError as e:
            raise InputError(f"render backend 'cpu' is not available in this build ({e}); "
                             f"use --set backend=torch") from None
    elif backend != "torch":
        raise InputError(f"unknown render backend {backend!r}; choose auto, torch, cpu or gsplat")
    return backend


__all__ = ["resolve_device", "resolve_backend_for", "gsplat_available"]
