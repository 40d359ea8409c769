"""What the local executor's forkserver loads once, before it forks each one-cell worker.

Importing this module imports the modules a cell and a shared-priors job run (gsbench.grids.running,
gsbench.grids.priors_share, with gsbench, torch and numba), the CPU kernels' modules and pycolmap,
then loads every numba kernel numba's on-disk cache holds for this machine
(gsbench/render/cached_kernels.py). Each worker then starts without its imports (about 3 s, pycolmap
0.3 s of it) and without loading the kernels (about 0.45 s).
Nothing here runs a kernel, a torch op or CUDA, so no torch thread pool, OpenMP team or CUDA context
exists when the server forks; loading a parallel kernel starts numba's threading layer, and its tbb
and workqueue layers are fork-safe (numba joins or resets their workers around fork()).
"""
from __future__ import annotations

import logging
import time

import gsbench  # noqa: F401  (first: gsbench's start-up settings)
import gsbench.grids.priors_share  # noqa: F401
import gsbench.grids.running  # noqa: F401
import gsbench.render.cpu_backend  # noqa: F401  (the renderer's kernels)
import gsbench.train.losses_cpu  # noqa: F401  (the losses' kernels)
import gsbench.train.ssim_cpu  # noqa: F401  (the training SSIM's kernels)
from gsbench.colmap_lib import import_pycolmap
from gsbench.render.cached_kernels import load_cached_kernels

log = logging.getLogger(__name__)

_t0 = time.perf_counter()
import_pycolmap()   # every cell and priors job writes or reads a COLMAP model: about 0.3 s each, and no thread
KERNELS_LOADED = load_cached_kernels()
log.debug("forkserver: %d cached numba kernels loaded in %.2f s", KERNELS_LOADED, time.perf_counter() - _t0)
