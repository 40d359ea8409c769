"""Functions the executor tests run in worker processes: a worker imports them by module name, so
they live in an importable helper module, not in a test file (pytest's importlib mode)."""
from __future__ import annotations

import os


def worker_info(x: int) -> tuple[int, str, str, int]:
    """x squared, the worker's thread settings and its pid."""
    return x * x, os.environ.get("OMP_NUM_THREADS", ""), os.environ.get("GSBENCH_THREADS", ""), os.getpid()


def worker_pools(_: int) -> dict:
    """The worker's parent, its torch thread count and its BLAS / OpenMP pools' sizes (threadpoolctl)."""
    import sys

    import numpy  # noqa: F401  (so numpy's BLAS is among the pools)
    import torch
    from threadpoolctl import threadpool_info
    return {"ppid": os.getppid(), "pid": os.getpid(), "torch": torch.get_num_threads(),
            "pools": sorted({p["num_threads"] for p in threadpool_info()}),
            "preloaded": "gsbench.grids.running" in sys.modules}
