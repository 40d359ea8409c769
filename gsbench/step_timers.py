"""Wall-time totals of the parts of a training step (named timers), for benchmarks/train_speed.py.

Off by default (a disabled `timed` block costs one function call). When enabled, the `cpu` render
backend adds `projection`, `raster_forward`, `raster_backward` and `projection_backward`, and the
trainer adds `losses` (the method's loss terms), `backward` (the whole autograd pass, the renderer's
backward included), `optimiser` and `densify` (statistics, densification, opacity reset). Times are
host wall times: on CUDA they measure launches, not kernels, so only CPU figures are meaningful.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from typing import Iterator

_totals: dict[str, float] = {}
_enabled = False


def enable(on: bool = True) -> None:
    """Start (or stop) accumulating; totals are kept until `reset`."""
    global _enabled
    _enabled = bool(on)


def reset() -> None:
    _totals.clear()


def totals() -> dict[str, float]:
    """Seconds per timer since the last `reset`."""
    return dict(_totals)


@contextmanager
def timed(name: str) -> Iterator[None]:
    """Add the wall time of the block to timer `name` when enabled."""
    if not _enabled:
        yield
        return
    t0 = time.perf_counter()
    try:
        yield
    finally:
        _totals[name] = _totals.get(name, 0.0) + time.perf_counter() - t0
