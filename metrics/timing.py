"""FPS timer: warm-up calls, device synchronisation around every timed call, median.

The median (not the mean) is robust to the occasional scheduler hiccup on shared machines.
`sync=None` picks the synchronisation automatically: with `device` given, `torch.cuda.synchronize(device)`
for a CUDA device (asynchronous kernels would otherwise be timed at launch; the device the work runs
on, not the current one) and none for the CPU (synchronous); without it, `torch.cuda.synchronize()`
when CUDA is initialised, else none. A callable is used as given and recorded by its name.
"""
from __future__ import annotations

import statistics
import time
from typing import Any, Callable

FPS_IMPL = "fps/median-after-warmup/v1"


def _auto_sync(device: Any = None) -> tuple[Callable[[], None] | None, str]:
    try:
        import torch
        if device is not None:
            dev = torch.device(device)
            if dev.type == "cuda":
                return (lambda: torch.cuda.synchronize(dev)), f"torch.cuda.synchronize({dev})"
            return None, f"none ({dev.type}, synchronous)"
        if torch.cuda.is_available() and torch.cuda.is_initialized():
            return torch.cuda.synchronize, "torch.cuda.synchronize"
    except ImportError:  # pragma: no cover
        pass
    return None, "none (cpu, synchronous)"


def time_fps(fn: Callable[[], Any], warmup: int = 3, repeats: int = 10,
             sync: Callable[[], None] | None = None, device: Any = None) -> dict:
    """Time `fn()` (its work on `device` when given); returns {"median_ms", "fps", "times_ms", "warmup",
    "repeats", "sync", "impl"}."""
    if warmup < 0 or repeats < 1:
        raise ValueError(f"need warmup >= 0 and repeats >= 1, got {warmup}, {repeats}")
    if sync is None:
        sync_fn, sync_name = _auto_sync(device)
    else:
        sync_fn, sync_name = sync, getattr(sync, "__qualname__", None) or repr(sync)
    for _ in range(warmup):
        fn()
    if sync_fn is not None:
        sync_fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        if sync_fn is not None:
            sync_fn()
        times.append((time.perf_counter() - t0) * 1000.0)
    med = statistics.median(times)
    # perf_counter resolution is well below a microsecond; guard the division anyway
    fps = 1000.0 / med if med > 0 else None
    return {"median_ms": med, "fps": fps, "times_ms": times, "warmup": warmup, "repeats": repeats,
            "sync": sync_name, "impl": FPS_IMPL}
