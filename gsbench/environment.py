"""The machine a run ran on, and the peak memory of one phase of one run.

`env_info()` is the one environment capture (env.json of a run, `machine` of results.json).

`PeakMemory` measures the peak of a phase (training, evaluation) on its own. ru_maxrss is the peak of
the whole process, so a process that ran a bigger run before would report that run's peak; on Linux
the peak (VmHWM) is reset at the start of the phase by writing 5 to /proc/self/clear_refs, and on
CUDA the allocator's peak by torch.cuda.reset_peak_memory_stats. (Linux derives ru_maxrss from the
same counter, so after a reset ru_maxrss too reports the peak since the reset.) Where the reset is not possible
the figure is the process lifetime peak, and `rss_source` says so. Grid cells also run in a fresh
process each (gsbench.grids.executors), so nothing carries over between cells either way.
"""
from __future__ import annotations

import hashlib
import logging
import os
import platform
import resource
import socket
import subprocess
import sys
from pathlib import Path
from typing import Optional

from gsbench.numerics import NUMERICS_VERSION

log = logging.getLogger(__name__)

RSS_RESET = "VmHWM after clear_refs reset"
RSS_LIFETIME = "ru_maxrss (process lifetime)"


def gsbench_version() -> Optional[str]:
    """The installed gsbench distribution's version (None when it is not installed as a package)."""
    from importlib import metadata
    try:
        return metadata.version("gsbench")
    except metadata.PackageNotFoundError:
        return None


def git_state() -> tuple[Optional[str], Optional[bool]]:
    """(HEAD commit, whether tracked files differ from it) of the gsbench checkout this code runs from;
    (None, None) when the package folder is not in a git work tree of gsbench (e.g. a wheel install) or
    git is missing. A run from uncommitted code is then not credited to HEAD alone. Read-only."""
    pkg = Path(__file__).resolve().parent

    def git(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(["git", *args], cwd=pkg, capture_output=True, text=True, timeout=5)
    try:
        top = git("rev-parse", "--show-toplevel")
        if top.returncode != 0 or Path(top.stdout.strip()).resolve() != pkg.parent:
            return None, None
        head = git("rev-parse", "HEAD")
        status = git("status", "--porcelain", "--untracked-files=no")
    except (OSError, subprocess.SubprocessError):
        return None, None
    sha = head.stdout.strip()
    if head.returncode != 0 or not sha:
        return None, None
    return sha, (bool(status.stdout.strip()) if status.returncode == 0 else None)


def package_version(name: str) -> Optional[str]:
    """An installed distribution's version without importing it (None when it is not installed)."""
    from importlib import metadata
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def cpu_facts() -> dict:
    """The CPU's model name, a short hash of its feature flags and its physical core count, from
    /proc/cpuinfo (None each where it does not say): two machines with the same model and flags run
    the CPU kernels with the same instructions, so `gsbench verify` compares their numbers exactly."""
    model = flags = None
    cores: set[tuple[str, str]] = set()
    physical = "0"
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                key, _, value = (part.strip() for part in line.partition(":"))
                if key == "model name" and model is None:
                    model = value
                elif key in ("flags", "Features") and flags is None:
                    flags = hashlib.sha256(" ".join(sorted(value.split())).encode()).hexdigest()[:16]
                elif key == "physical id":
                    physical = value
                elif key == "core id":
                    cores.add((physical, value))
    except OSError:
        pass
    return {"cpu_model": model or platform.processor() or None, "cpu_flags": flags,
            "physical_cores": len(cores) or None}


def env_info() -> dict:
    """Host, hardware and software versions (the fields results compare runs by), and the numerics
    version the run's numbers belong to (gsbench.numerics)."""
    import numpy as np
    import torch
    cuda = torch.cuda.get_device_name(torch.cuda.current_device()) if torch.cuda.is_available() else None
    sha, dirty = git_state()
    return {"host": socket.gethostname(), "cpu": platform.processor() or platform.machine(),
            "cores": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
            "torch": torch.__version__, "numpy": np.__version__, "torch_threads": torch.get_num_threads(),
            "cuda": cuda, "gsbench": gsbench_version(), "git_sha": sha, "git_dirty": dirty, **cpu_facts(),
            "numba": package_version("numba"), "numerics_version": NUMERICS_VERSION}


def lifetime_peak_rss_mb() -> float:
    """Peak resident memory of this process since it started (Linux reports KiB, macOS bytes)."""
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return float(r) / 2**20 if sys.platform == "darwin" else float(r) / 1024.0


def _vm_hwm_mb() -> Optional[float]:
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        return None
    return None


def _reset_rss_peak() -> bool:
    """Reset this process's VmHWM to its current RSS (Linux >= 4.0); False where that is not possible."""
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as f:
            f.write("5")
    except OSError:
        return False
    return _vm_hwm_mb() is not None


def _cuda_device(device: object) -> Optional[object]:
    if device is None:
        return None
    import torch
    dev = torch.device(device) if not isinstance(device, torch.device) else device
    return dev if dev.type == "cuda" and torch.cuda.is_available() else None


class PeakMemory:
    """Peak RSS (and CUDA allocator peak on a CUDA device) between start() and read()."""

    def __init__(self, device: object = None) -> None:
        self.device = device
        self.rss_source = RSS_LIFETIME
        self._cuda = None

    def start(self) -> "PeakMemory":
        self.rss_source = RSS_RESET if _reset_rss_peak() else RSS_LIFETIME
        self._cuda = _cuda_device(self.device)
        if self._cuda is not None:
            import torch
            torch.cuda.synchronize(self._cuda)
            torch.cuda.reset_peak_memory_stats(self._cuda)
        return self

    def read(self) -> dict:
        """{"peak_rss_mb", "rss_source"} plus "peak_cuda_mb" when the phase ran on a CUDA device."""
        hwm = _vm_hwm_mb() if self.rss_source == RSS_RESET else None
        out: dict = {"peak_rss_mb": hwm if hwm is not None else lifetime_peak_rss_mb(),
                     "rss_source": self.rss_source if hwm is not None else RSS_LIFETIME}
        if self._cuda is not None:
            import torch
            torch.cuda.synchronize(self._cuda)
            out["peak_cuda_mb"] = torch.cuda.max_memory_allocated(self._cuda) / 2**20
        return out

    def __enter__(self) -> "PeakMemory":
        return self.start()

    def __exit__(self, *exc) -> None:
        return None
