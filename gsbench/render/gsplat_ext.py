"""Whether gsplat can render here, found without compiling anything, and the one explicit build.

`import gsplat` succeeds without its CUDA extension: gsplat (1.5) loads or builds the extension
lazily, at the first rasterization call (`gsplat.cuda._backend._C`). A wheel with the extension
inside has the module `gsplat.csrc`; otherwise the extension is compiled by torch's JIT into
`<torch extensions dir>/gsplat_cuda/` (minutes, once per machine), and without a CUDA toolkit
(nvcc) `_C` stays None and the first render raises AttributeError. `gsplat_status()` tells these
cases apart by looking for the files only; `build_gsplat_extension()` does the build (or the quick
load of a cached one) in the calling process, with a log line, so it never happens silently inside
a training step or in several grid workers at once.
"""
from __future__ import annotations

import importlib.util
import logging
import os
import shutil
import sys
import time
from dataclasses import dataclass

from gsbench.errors import InputError

log = logging.getLogger(__name__)

EXTENSION = "gsplat_cuda"      # gsplat's JIT extension name (its build folder)
# the states, best first; the first three can render (needs-build after the one-time compile)
READY, CACHED, NEEDS_BUILD, NO_TOOLKIT, MISSING = "ready", "cached", "needs-build", "no-toolkit", "missing"
USABLE = (READY, CACHED, NEEDS_BUILD)


@dataclass(frozen=True)
class GsplatStatus:
    state: str          # one of ready | cached | needs-build | no-toolkit | missing
    version: str | None
    detail: str         # one line for a log or `gsbench doctor`

    @property
    def usable(self) -> bool:
        return self.state in USABLE


def _build_dir() -> str | None:
    """torch's JIT build folder of gsplat's extension (the one gsplat 1.5 uses); None when unknown."""
    try:
        from torch.utils.cpp_extension import _get_build_directory
        return _get_build_directory(EXTENSION, verbose=False)
    except Exception:   # noqa: BLE001 - a private torch helper: any failure means "unknown"
        return None


def _nvcc() -> str | None:
    """The nvcc gsplat's JIT build would use: CUDA_HOME/bin/nvcc, else nvcc on PATH."""
    try:
        from torch.utils.cpp_extension import CUDA_HOME
    except Exception:   # noqa: BLE001
        CUDA_HOME = None
    if CUDA_HOME and os.path.isfile(os.path.join(CUDA_HOME, "bin", "nvcc")):
        return os.path.join(CUDA_HOME, "bin", "nvcc")
    return shutil.which("nvcc")


def gsplat_status() -> GsplatStatus:
    """What the first gsplat render would do here: nothing (ready), load a cached build (cached),
    compile for minutes (needs-build), fail (no-toolkit), or the package is not importable (missing).
    Never compiles or loads the extension."""
    try:
        import gsplat
    except Exception as e:   # noqa: BLE001 - a broken CUDA build raises more than ImportError
        return GsplatStatus(MISSING, None, f"not importable ({type(e).__name__}: {e}); pip install 'gsbench[cuda]'")
    version = str(getattr(gsplat, "__version__", "unknown"))
    backend = sys.modules.get("gsplat.cuda._backend")
    if backend is not None:      # already loaded in this process: its _C is the answer
        if getattr(backend, "_C", None) is not None:
            return GsplatStatus(READY, version, "CUDA extension loaded")
        return GsplatStatus(NO_TOOLKIT, version, "CUDA extension failed to load in this process (_C is None)")
    try:
        prebuilt = importlib.util.find_spec("gsplat.csrc") is not None
    except (ImportError, ValueError):
        prebuilt = False
    if prebuilt:
        return GsplatStatus(READY, version, "CUDA extension shipped with the package (gsplat.csrc)")
    build = _build_dir()
    if build and any(os.path.exists(os.path.join(build, EXTENSION + ext)) for ext in (".so", ".lib")):
        return GsplatStatus(CACHED, version, f"CUDA extension compiled earlier, loads from {build}")
    nvcc = _nvcc()
    if nvcc:
        return GsplatStatus(NEEDS_BUILD, version,
                            f"CUDA extension not built: the first use compiles it with {nvcc} into "
                            f"{build or 'the torch extensions folder'} (minutes, once per machine)")
    return GsplatStatus(NO_TOOLKIT, version, "no CUDA extension and no CUDA toolkit (nvcc) to build it: gsplat "
                                             "cannot render here; install a gsplat wheel built for this torch/CUDA "
                                             "or the CUDA toolkit")


def build_gsplat_extension() -> GsplatStatus:
    """Load gsplat's CUDA extension in this process, compiling it first when needed (logged, timed).

    Raises InputError when it cannot be had. Done before training (and once in a grid's parent
    process), so a compile is announced and never runs in several workers at once."""
    st = gsplat_status()
    if st.state == READY:
        return st
    if not st.usable:
        raise InputError(f"backend gsplat: gsplat {st.version or ''} {st.detail}".replace("  ", " "))
    if st.state == NEEDS_BUILD:
        log.warning("gsplat %s: compiling its CUDA extension now (once per machine; about 90 s with MAX_JOBS=16 "
                    "and TORCH_CUDA_ARCH_LIST set to this GPU, several minutes with fewer cores)", st.version)
    t0 = time.perf_counter()
    try:
        from gsplat.cuda._backend import _C
    except Exception as e:   # noqa: BLE001 - compiler errors surface as many exception types
        raise InputError(f"backend gsplat: building gsplat's CUDA extension failed: {type(e).__name__}: {e}") from None
    if _C is None:
        raise InputError("backend gsplat: gsplat's CUDA extension did not load (no CUDA toolkit found by gsplat)")
    if st.state == NEEDS_BUILD:
        log.warning("gsplat: CUDA extension built in %.0f s", time.perf_counter() - t0)
    return gsplat_status()


__all__ = ["GsplatStatus", "gsplat_status", "build_gsplat_extension", "USABLE", "READY", "CACHED", "NEEDS_BUILD",
           "NO_TOOLKIT", "MISSING"]
