"""gsbench: a benchmark and evaluation harness for semantic 3D Gaussian Splatting.

Process-wide settings are made once, by `startup()`, which `import gsbench` calls (so they hold for
library use and for the CLI alike, before any gsbench module imports torch):

- GOMP_SPINCOUNT=0 unless the environment sets it: PyTorch's OpenMP workers sleep as soon as a
  parallel op ends. Left spinning (libgomp's default is 300,000 spins, milliseconds), they compete with
  the `cpu` render backend's and the CPU losses' numba threads for the cores: on a 2-core machine
  that made a training step ~1.5x slower. 30,000 spins, the earlier setting, still cost a numba kernel
  that followed a PyTorch op about 0.5 ms, and whole cpu-medium trainings were 4-11 % slower than with
  0 (docs/benchmarks.md, "Two threads"). It has no effect when torch was imported before gsbench.
- torch.set_flush_denormal(True): denormal floats are flushed to zero on CPU, so the render and
  trainer never hit the slow denormal path. The flag belongs to the thread that calls startup (the
  main thread; worker processes call it when they import gsbench).
"""
import logging as _logging
import os as _os

__version__ = "0.1.0"

_log = _logging.getLogger(__name__)
_STARTED = False


def startup() -> None:
    """Make the process-wide settings once; later calls do nothing."""
    global _STARTED
    if _STARTED:
        return
    _STARTED = True
    _os.environ.setdefault("GOMP_SPINCOUNT", "0")
    import torch
    torch.set_flush_denormal(True)
    _log.debug("startup: GOMP_SPINCOUNT=%s, flush denormals on", _os.environ["GOMP_SPINCOUNT"])


startup()
