"""Functions the executor tests run in worker processes: a worker imports them by module name, so
they live in an importable helper module, not in a test file (pytest's importlib mode)."""
from __future__ import annotations

import os


def worker_info(x: int) -> tuple[int, str, str, int]:
    """x squared, the worker's thread settings and its pid."""
    return x * x, os.environ.get("OMP_NUM_THREADS", ""), os.environ.get("GSBENCH_THREADS", ""), os.getpid()
