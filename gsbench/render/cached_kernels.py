"""Load the numba kernels' machine code from numba's on-disk cache, without compiling anything.

Why: a numba kernel with `cache=True` is loaded from the cache on its first call, in every process.
A grid's one-cell worker paid about a second for that before its first step. The local executor's
forkserver calls `load_cached_kernels` once (gsbench/grids/worker_preload.py), so the workers it
forks start with every cached kernel loaded. Only entries the cache holds for this machine's CPU and
the current source are loaded; a kernel or signature the cache lacks is compiled on first call as
before. The code is the cache's own, so the bits are those of a kernel loaded on first call.

Loading a parallel kernel starts numba's threading layer. `tbb` and `workqueue` are safe to fork
after that (numba joins or resets their threads around fork()); GNU OpenMP (`omp`) is not, so
nothing is loaded under it.
"""
from __future__ import annotations

import logging
import os
import sys
from types import ModuleType
from typing import Iterable, Optional

log = logging.getLogger(__name__)

FORK_SAFE_LAYERS = ("tbb", "workqueue")


def _cached_signatures(dispatcher) -> list:
    """The signatures `dispatcher`'s cache index holds for this CPU and the current source."""
    cache = dispatcher._cache                      # numba's FunctionCache (NullCache without cache=True)
    cache_file = getattr(cache, "_cache_file", None)
    if cache_file is None:
        return []
    codegen = dispatcher.targetctx.codegen()
    return [key[0] for key in cache_file._load_index() if key == cache._index_key(key[0], codegen)]


def cached_dispatchers(modules: Iterable[ModuleType]) -> list:
    """The numba CPU dispatchers with an on-disk cache defined in `modules` (by their own module)."""
    from numba.core.registry import CPUDispatcher
    seen, out = set(), []
    for module in modules:
        for value in vars(module).values():
            if (isinstance(value, CPUDispatcher) and value.__module__ == module.__name__
                    and id(value) not in seen and value._cache.__class__.__name__ != "NullCache"):
                seen.add(id(value))
                out.append(value)
    return out


def load_cached_kernels(modules: Optional[Iterable[ModuleType]] = None) -> int:
    """Load every cached signature of the numba kernels in `modules` (default: the imported gsbench
    modules) and return how many were loaded. Nothing when numba's threading layer is not fork-safe;
    a cache numba cannot read is logged and skipped (the kernels then load on first call)."""
    layer = os.environ.get("NUMBA_THREADING_LAYER", "default")
    if layer not in FORK_SAFE_LAYERS:
        log.info("numba kernels not preloaded: threading layer %s is not known to be fork-safe", layer)
        return 0
    if modules is None:
        modules = [m for name, m in list(sys.modules.items()) if name.startswith("gsbench.") and m is not None]
    loaded = 0
    for dispatcher in cached_dispatchers(modules):
        try:
            for sig in _cached_signatures(dispatcher):
                dispatcher.compile(sig)             # a cache hit: numba loads the entry, it does not compile
                loaded += 1
        except Exception as e:   # noqa: BLE001  numba's cache internals changed, or an unreadable cache
            # file: only the preload is lost, the kernel loads (or fails, with its error) on first call
            log.info("numba kernel %s not preloaded (%s: %s)", dispatcher.__name__, type(e).__name__, e)
    return loaded


__all__ = ["load_cached_kernels", "cached_dispatchers", "FORK_SAFE_LAYERS"]
