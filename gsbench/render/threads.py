"""The CPU threads of the `cpu` backend: numba's threading layer, and a training step's thread budget.

numba's threading layer (`select_numba_threading_layer`, applied when gsbench.render is imported,
before any kernel runs): NUMBA_THREADING_LAYER when set; else `tbb` when the `tbb` package is
installed (a core dependency on x86-64) and its library is new enough for numba; else `workqueue`.
The kernels give the same bits on every layer (each pixel and gradient row is one task's, in a
fixed order), so the layer changes speed only. Why tbb: a parallel kernel launch on `workqueue`
wakes its sleeping pool, 80-90 us back to back and about 170 us after a millisecond of other work
on this 2-core VM, against 2 and 10 us on tbb, whose workers spin briefly before they sleep; a
training step launches about a dozen parallel kernels, and cpu-medium's step went from 42 to 32 ms
(docs/benchmarks.md). pip's tbb puts its library outside the loader's search path, so it is loaded
here, by its path, before numba looks for it. numba's `omp` layer is not chosen: it loads the
system libgomp next to PyTorch's own, and the two runtimes' spinning workers slowed PyTorch's ops
10-30x. The layer in use is recorded in each run's train_summary.json.

The thread budget of a training step: numba kernels on all of it, PyTorch's ops on one thread.

Inside `torch_ops_serial()` (the trainer wraps each CPU step in it) PyTorch runs on one thread and
the `cpu` backend's numba kernels on the threads PyTorch had (`kernel_threads`). Why:
- a training step runs about sixty small PyTorch ops (tens of thousands of elements: SH colours,
  loss glue, autograd, Adam, densification statistics); on two cores each parallel one paid the
  OpenMP team's wake-up, about 3 ms per step in all at 19k Gaussians (docs/benchmarks.md);
- PyTorch's parallel reductions split their work by the thread count, so a run's results depended
  on it. With PyTorch's ops serial and the numba kernels bit-identical for any thread count by
  construction, a CPU run gives the same bits whatever its thread budget (GSBENCH_THREADS).
Outside the block (evaluation, the autoencoder's decode) PyTorch keeps its threads.
"""
from __future__ import annotations

import ctypes
import importlib.metadata
import logging
import os
import sys
from contextlib import contextmanager
from typing import Iterator, Optional

import torch

log = logging.getLogger(__name__)

_LIBTBB = {"linux": "libtbb.so.12", "darwin": "libtbb.12.dylib"}   # the names numba loads
TBB_MIN_INTERFACE = 12060                  # TBB 2021.6: the oldest numba's tbb layer accepts

_kernel_threads: Optional[int] = None     # set inside torch_ops_serial()


def kernel_threads() -> int:
    """Threads the numba kernels may use: PyTorch's thread count, or inside `torch_ops_serial()` the
    count PyTorch had when the block began."""
    return _kernel_threads if _kernel_threads is not None else torch.get_num_threads()


@contextmanager
def torch_ops_serial() -> Iterator[None]:
    """Run the block's PyTorch ops on one thread; the numba kernels keep the threads PyTorch had.
    Both are restored on exit, also on an error."""
    global _kernel_threads
    before, outer = torch.get_num_threads(), _kernel_threads
    _kernel_threads = kernel_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)
        _kernel_threads = outer


def _load_tbb() -> bool:
    """Load the `tbb` package's library globally (so numba's tbb layer finds it by name); True when
    it loaded and is new enough for numba."""
    name = _LIBTBB.get(sys.platform)
    try:
        dist = importlib.metadata.distribution("tbb")
    except importlib.metadata.PackageNotFoundError:
        return False
    path = next((dist.locate_file(f) for f in (dist.files or ()) if f.name == name), None)
    if path is None:
        return False
    try:
        lib = ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
        version = lib.TBB_runtime_interface_version
        version.restype = ctypes.c_int
        ok = int(version()) >= TBB_MIN_INTERFACE
    except (OSError, AttributeError) as e:
        log.info("tbb's library %s did not load (%s): numba uses workqueue", path, e)
        return False
    if not ok:
        log.info("tbb's library %s is older than numba accepts: numba uses workqueue", path)
    return ok


_chosen: Optional[str] = None     # the layer select_numba_threading_layer set itself (not the user)


def select_numba_threading_layer() -> str:
    """Choose numba's threading layer (module docstring) unless NUMBA_THREADING_LAYER is set, and
    return it. Set in the environment, which numba reads; call before the first parallel kernel."""
    global _chosen
    layer = os.environ.get("NUMBA_THREADING_LAYER")
    if layer and (layer == _chosen or layer != "tbb"):
        return layer                  # chosen by an earlier call, or the user's (not tbb)
    loaded = _load_tbb()          # also when the user asked for tbb: numba finds pip's library only so
    if not layer:
        layer = "tbb" if loaded else "workqueue"
        os.environ["NUMBA_THREADING_LAYER"] = layer
        _chosen = layer
    return layer


def tbb_unusable(reason: BaseException) -> str:
    """numba could not load its tbb layer (`reason`): when gsbench chose tbb, use `workqueue` instead
    (the same bits, slower launches; logged, and recorded in train_summary.json) and return it; when
    the user asked for tbb, raise."""
    global _chosen
    if _chosen != "tbb" or os.environ.get("NUMBA_THREADING_LAYER") != "tbb":
        raise reason
    log.warning("numba's tbb threading layer did not load (%s): the cpu kernels use workqueue", reason)
    os.environ["NUMBA_THREADING_LAYER"] = _chosen = "workqueue"
    return "workqueue"


def numba_threading_layer() -> Optional[str]:
    """The layer `select_numba_threading_layer` chose (or the user set); None before it ran."""
    return os.environ.get("NUMBA_THREADING_LAYER")


__all__ = ["kernel_threads", "torch_ops_serial", "select_numba_threading_layer", "numba_threading_layer",
           "tbb_unusable"]
