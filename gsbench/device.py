"""Where work runs: the one device rule of gsbench. Training resolves `train.device` (auto | cpu |
cuda | cuda:N) once, up front; a model prior without a device of its own takes `default_device()`.

Everything a training step touches (field, Adam state, images, priors, autoencoder, losses,
densification statistics) is created on or moved to the training device, so a step never copies to
the host. Asking for CUDA where there is none is an error, never a silent CPU fallback.
"""
from __future__ import annotations

import torch

from gsbench.config import setting
from gsbench.errors import InputError

CPU_ONLY_BACKENDS = ("cpu",)    # backends that render CPU tensors only: `auto` devices follow them


def default_device() -> str:
    """"cuda" when CUDA is available, else "cpu": the device of a model prior given none."""
    return "cuda" if torch.cuda.is_available() else "cpu"


def resolve_device(config: dict) -> torch.device:
    """The torch device of `train.device`. 'auto' = the CPU when the config's backend renders on the
    CPU only (backend: cpu, as the CPU presets pin it), else cuda:0 when CUDA is available, else the CPU.

    Asking for CUDA on a machine without it is a one-line InputError (no silent CPU fallback)."""
    want = str(setting(config, "train.device") or "auto").strip().lower()
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


__all__ = ["CPU_ONLY_BACKENDS", "default_device", "resolve_device"]
