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


def worker_kernels(seed: int) -> dict:
    """Which cpu-backend kernels the worker had loaded before it ran anything, then one render's
    outputs (forward and backward through the parallel kernels) for comparison with another process."""
    import sys

    from gsbench.render import cpu_kernels
    before = {"raster_forward": len(cpu_kernels.raster_forward.signatures),
              "raster_backward": len(cpu_kernels.raster_backward.signatures),
              "pycolmap": "pycolmap" in sys.modules}
    return {"loaded": before, **render_once(seed)}


def render_once(seed: int) -> dict:
    """A float32 forward and backward render of a small random field with the cpu backend, as numpy."""
    import torch
    from render_fields import look_at, random_field, with_grad

    from gsbench.render import render
    field = with_grad(random_field(64, seed, dtype=torch.float32))
    out = render(field, look_at(24, 16, eye=(0.0, 0.0, -3.0)), backend="cpu")
    (out.rgb.sum() + out.depth.sum() + out.features.sum()).backward()
    return {"rgb": out.rgb.detach().numpy(), "means_grad": field.means.grad.numpy()}
