"""Executors: run a function over a list of picklable items and return the results in order.

The grid code only calls `executor.map(fn, items)`; it does not know which executor runs it.

- `LocalExecutor(jobs)`: a process pool that starts a fresh worker process for every cell
  (max_tasks_per_child=1), so no cell inherits the memory peak, caches or torch state of an earlier
  one; each worker uses max(1, cores // jobs) threads (torch, numba, BLAS) so `--jobs N` never
  oversubscribes the machine. Workers are forked from a forkserver that has imported gsbench, torch,
  numba and pycolmap and loaded the cached numba kernels once (`WORKER_PRELOAD`, gsbench/grids/worker_preload.py)
  and run nothing: no torch thread pool, OpenMP team or CUDA context exists there to be forked (numba's
  tbb or workqueue pool is fork-safe), and each cell starts without its ~3 s of imports and ~0.45 s
  of kernel loading. On a CUDA machine each
  worker takes a GPU from a pool of `jobs` slots (slot k on the (k % n)-th GPU this process sees) and
  gives it back when it exits. A worker's CUDA_VISIBLE_DEVICES is that GPU's entry of the parent's own
  list (an index or a UUID), so under CUDA_VISIBLE_DEVICES=2,3 the workers use GPUs 2 and 3, not 0 and 1.
- `SerialExecutor()`: in this process, one cell after another (debugging).
- `SubmititExecutor(folder, cluster)`: submitit job arrays (`map_array`). cluster="slurm" submits
  to SLURM, cluster="local" runs each job as a local subprocess (used in the tests), "debug" runs
  in-process. SLURM parameters (partition, time, cpus, gpus, array parallelism) pass through.
"""
from __future__ import annotations

import functools
import os
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from multiprocessing import util as mp_util
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

from tqdm import tqdm

from gsbench.errors import InputError

EXECUTORS = ("local", "submitit", "serial")
# what the local executor's forkserver imports before it forks the workers (the cell and priors jobs'
# modules, and the cached numba kernels)
WORKER_PRELOAD = ["gsbench.grids.worker_preload"]


class SerialExecutor:
    """Cells one after another in this process (debugging; a crash takes the grid down with it)."""

    name = "serial"

    def __init__(self, progress: bool = True) -> None:
        self.progress = progress

    def map(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> list[Any]:
        return [fn(item) for item in tqdm(list(items), desc="cells (serial)", disable=not self.progress)]


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - non-Linux
        return os.cpu_count() or 1


def _init_worker(threads: int, gpu_queue: Any) -> None:
    """Per-worker set-up: thread budget and (when there are GPUs) one GPU per worker.

    The budget goes into OMP_NUM_THREADS / MKL_NUM_THREADS / GSBENCH_THREADS (for what a cell starts);
    the forkserver imported torch and numpy before it, so torch.set_num_threads (`apply_thread_budget()`)
    and the BLAS and OpenMP pools' limits (threadpoolctl) apply it in this process."""
    os.environ["OMP_NUM_THREADS"] = str(threads)
    os.environ["MKL_NUM_THREADS"] = str(threads)
    os.environ["GSBENCH_THREADS"] = str(threads)
    from threadpoolctl import threadpool_limits
    threadpool_limits(limits=threads)
    if gpu_queue is not None:
        gpu = gpu_queue.get()
        os.environ["CUDA_VISIBLE_DEVICES"] = str(gpu)
        # the slot goes back when this one-cell worker exits, for the worker that replaces it
        mp_util.Finalize(None, gpu_queue.put, args=(gpu,), exitpriority=10)
    if "torch" in sys.modules:
        apply_thread_budget()


def apply_thread_budget() -> Optional[int]:
    """torch.set_num_threads(GSBENCH_THREADS) when an executor set a budget for this process."""
    n = os.environ.get("GSBENCH_THREADS")
    if not n:
        return None
    import torch
    torch.set_num_threads(int(n))
    return int(n)


class LocalExecutor:
    """A forkserver-context process pool with `jobs` workers, one process per item."""

    name = "local"

    def __init__(self, jobs: int = 1, threads: Optional[int] = None, progress: bool = True) -> None:
        if jobs < 1:
            raise InputError(f"--jobs must be >= 1, got {jobs}")
        self.jobs = jobs
        self.threads = threads if threads is not None else max(1, _cpu_count() // jobs)
        self.progress = progress

    def map(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> list[Any]:
        items = list(items)
        if not items:
            return []
        ctx = get_context("forkserver")
        ctx.set_forkserver_preload(WORKER_PRELOAD)
        gpu_queue = None
        slots = gpu_slots(self.jobs, _gpu_count(), os.environ.get("CUDA_VISIBLE_DEVICES"))
        if slots:
            gpu_queue = ctx.Manager().Queue()
            for gpu in slots:
                gpu_queue.put(gpu)
        results: list[Any] = [None] * len(items)
        with ProcessPoolExecutor(max_workers=min(self.jobs, len(items)), mp_context=ctx, max_tasks_per_child=1,
                                 initializer=_init_worker, initargs=(self.threads, gpu_queue)) as pool:
            futures = {pool.submit(fn, item): i for i, item in enumerate(items)}
            bar = tqdm(total=len(items), desc=f"cells (local, {self.jobs} jobs)", disable=not self.progress)
            for fut in as_completed(futures):
                results[futures[fut]] = fut.result()
                bar.update(1)
            bar.close()
        return results


def gpu_slots(jobs: int, n_gpus: int, visible: Optional[str]) -> list[str]:
    """The CUDA_VISIBLE_DEVICES value of each of `jobs` worker slots: slot k gets the (k % n)-th GPU
    this process sees, named as the parent's CUDA_VISIBLE_DEVICES names it (index, GPU-/MIG- UUID);
    without that variable the GPUs are 0..n-1. [] when there is no GPU."""
    if n_gpus <= 0:
        return []
    if visible is None:
        names = [str(i) for i in range(n_gpus)]
    else:   # CUDA reads the list up to its first invalid entry, so torch's count is a prefix of it
        names = [e.strip() for e in visible.split(",") if e.strip()][:n_gpus]
        if len(names) < n_gpus:
            raise InputError(f"CUDA_VISIBLE_DEVICES={visible!r} names {len(names)} device(s) but torch sees "
                             f"{n_gpus}; cannot tell which GPU each worker should use")
    return [names[k % n_gpus] for k in range(jobs)]


def _gpu_count() -> int:
    try:
        import torch
        return torch.cuda.device_count() if torch.cuda.is_available() else 0
    except Exception:  # pragma: no cover
        return 0


def _call_with_threads(fn: Callable[[Any], Any], threads: int, item: Any) -> Any:
    """Run fn(item) with a torch thread budget (submitit jobs start with the library default)."""
    _init_worker(threads, None)
    return fn(item)


class SubmititExecutor:
    """submitit job arrays; `cluster` is slurm (real cluster), local (subprocesses) or debug."""

    name = "submitit"

    def __init__(self, folder: str | os.PathLike, cluster: str = "slurm", progress: bool = True,
                 **parameters: Any) -> None:
        try:
            import submitit
        except ImportError:
            raise ImportError("the submitit executor needs `pip install submitit` (extra `cluster`)") from None
        if cluster not in ("slurm", "local", "debug"):
            raise InputError(f"submitit cluster must be slurm, local or debug, got {cluster!r}")
        self.folder = Path(folder)
        self.cluster = cluster
        self.threads = parameters.get("cpus_per_task")
        self.progress = progress
        self._executor = submitit.AutoExecutor(folder=str(self.folder / "%j"), cluster=cluster)
        params = {k: v for k, v in parameters.items() if v is not None}
        if params:
            self._executor.update_parameters(**params)

    def map(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> list[Any]:
        items = list(items)
        if not items:
            return []
        threads = self.threads or max(1, _cpu_count() // (len(items) if self.cluster == "local" else 1))
        jobs = self._executor.map_array(functools.partial(_call_with_threads, fn, threads), items)
        results = []
        bar = tqdm(total=len(jobs), desc=f"cells (submitit {self.cluster})", disable=not self.progress)
        for job in jobs:
            results.append(job.result())
            bar.update(1)
        bar.close()
        return results


def make_executor(kind: str, jobs: int = 1, folder: Optional[str | os.PathLike] = None,
                  cluster: str = "slurm", progress: bool = True, **slurm: Any) -> Any:
    """Build an executor by name (the CLI's --executor)."""
    if kind == "local":
        return LocalExecutor(jobs=jobs, progress=progress)
    if kind == "serial":
        return SerialExecutor(progress=progress)
    if kind == "submitit":
        if folder is None:
            raise ValueError("the submitit executor needs a log folder")
        params = dict(slurm)
        if cluster == "slurm" and jobs:
            params.setdefault("slurm_array_parallelism", jobs)
        return SubmititExecutor(folder, cluster=cluster, progress=progress, **params)
    raise InputError(f"unknown executor {kind!r}; choose one of {', '.join(EXECUTORS)}")
