"""Executors: results in order, thread budget per worker, submitit local mode."""
from __future__ import annotations

import math
import os

import pytest
from pool_jobs import worker_info, worker_pools

from gsbench.grids.executors import LocalExecutor, SubmititExecutor, apply_thread_budget, make_executor


def test_local_pool_keeps_order_and_sets_threads():
    ex = LocalExecutor(jobs=2, threads=1, progress=False)
    # 3 items on 2 workers: a worker is replaced (one cell per process) and results come back in item order
    out = ex.map(worker_info, [3, 1, 2])
    assert [o[0] for o in out] == [9, 1, 4]
    assert all(o[1] == "1" and o[2] == "1" for o in out)
    assert os.getpid() not in {o[3] for o in out}      # ran in worker processes


def test_local_workers_fork_from_a_preloaded_server_and_take_the_budget():
    """Workers are forked from the forkserver (not children of this process), one per item, and the
    budget reaches torch and the BLAS / OpenMP pools the server had loaded with this process's settings."""
    for threads in (1, 2):
        out = LocalExecutor(jobs=1, threads=threads, progress=False).map(worker_pools, [0, 1])
        assert len({o["pid"] for o in out}) == 2
        assert all(o["ppid"] != os.getpid() and o["preloaded"] for o in out)
        assert all(o["torch"] == threads and o["pools"] == [threads] for o in out), out


def test_thread_budget_applies_to_torch(monkeypatch):
    import torch
    before = torch.get_num_threads()
    monkeypatch.setenv("GSBENCH_THREADS", "1")
    try:
        assert apply_thread_budget() == 1
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)


def test_local_default_thread_budget():
    ex = LocalExecutor(jobs=2, progress=False)
    import os
    cores = len(os.sched_getaffinity(0))
    assert ex.threads == max(1, cores // 2)
    with pytest.raises(ValueError):
        LocalExecutor(jobs=0)


def test_submitit_local_mode_job_array(tmp_path):
    ex = SubmititExecutor(tmp_path / "logs", cluster="local", progress=False, timeout_min=5)
    out = ex.map(math.factorial, [4, 5])
    assert out == [24, 120]
    assert any((tmp_path / "logs").iterdir())          # submitit wrote its job folders


def test_make_executor_rejects_unknown():
    with pytest.raises(ValueError, match="unknown executor"):
        make_executor("dask")
    with pytest.raises(ValueError, match="cluster"):
        SubmititExecutor("x", cluster="pbs")


KERNELS_PROBE = """
import json, sys
import numpy as np
from pool_jobs import render_once, worker_kernels
from gsbench.grids.executors import LocalExecutor
here = [render_once(seed) for seed in (0, 1)]     # puts the kernels in numba's cache before the forkserver starts
checks = []
for threads in (1, 2):
    out = LocalExecutor(jobs=1, threads=threads, progress=False).map(worker_kernels, [0, 1])
    checks += [{"loaded": o["loaded"], "same": bool(np.array_equal(o["rgb"], h["rgb"])
                                                     and np.array_equal(o["means_grad"], h["means_grad"]))}
               for o, h in zip(out, here)]
print(json.dumps(checks))
"""


def test_local_workers_start_with_the_cached_kernels_loaded():
    """The forkserver imported pycolmap and loaded the kernels numba's cache holds, so a worker has them
    before its first render, and its renders (threads forked after the kernels loaded) give the bits
    of the process that started the pool. In a fresh process, so its forkserver starts after the
    cache holds the kernels."""
    import json
    import subprocess
    import sys

    from paths import REPO_ROOT

    from gsbench.render import cpu_kernels
    if not cpu_kernels.raster_forward.stats.cache_path:
        pytest.skip("numba caching is off")
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT / "tests" / "support")}
    res = subprocess.run([sys.executable, "-c", KERNELS_PROBE], env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    checks = json.loads(res.stdout.strip().splitlines()[-1])
    assert len(checks) == 4
    for c in checks:
        assert c["loaded"]["raster_forward"] >= 1 and c["loaded"]["raster_backward"] >= 1 and c["loaded"]["pycolmap"]
        assert c["same"]
