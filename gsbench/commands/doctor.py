"""`gsbench doctor`: what this machine can run, before a first run on it.

Prints torch and its CUDA build, the CUDA devices torch sees, gsplat with the state of its CUDA
extension (found from the files, never compiled here unless --build-gsplat asks), numba and the
`cpu` backend, and the device and render backend that each shipped preset resolves to with
`train.device: auto` (gsbench.render.resolve_backend: the same rule training uses).
"""
from __future__ import annotations

import argparse
import os
import platform

from gsbench.config import load_config, setting, shipped_presets
from gsbench.device import resolve_device
from gsbench.errors import InputError
from gsbench.render import resolve_backend
from gsbench.render.gsplat_ext import NEEDS_BUILD, build_gsplat_extension, gsplat_status


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--build-gsplat", action="store_true",
                        help="load gsplat's CUDA extension now, compiling it first when this machine has no build "
                             "(minutes, once per machine); training would otherwise do it before its first step")


def _torch_lines() -> list[str]:
    import torch
    lines = [f"python   {platform.python_version()}",
             f"torch    {torch.__version__} (built with CUDA {torch.version.cuda or 'none'})"]
    if not torch.cuda.is_available():
        lines.append("cuda     not available to torch" + ("" if torch.version.cuda else " (a CPU-only torch build)"))
        return lines
    vis = os.environ.get("CUDA_VISIBLE_DEVICES")
    lines.append(f"cuda     {torch.cuda.device_count()} device(s)"
                 + (f", CUDA_VISIBLE_DEVICES={vis}" if vis is not None else ""))
    for i in range(torch.cuda.device_count()):
        p = torch.cuda.get_device_properties(i)
        lines.append(f"  cuda:{i}  {p.name}, {p.total_memory / 2**30:.1f} GiB, compute capability {p.major}.{p.minor}")
    return lines


def _gsplat_lines() -> list[str]:
    st = gsplat_status()
    env = ", ".join(f"{k}={os.environ[k]}" for k in ("MAX_JOBS", "TORCH_CUDA_ARCH_LIST") if k in os.environ)
    lines = [f"gsplat   {st.version or '-'}: {st.state}: {st.detail}"]
    if st.state == NEEDS_BUILD:
        lines.append("  `gsbench doctor --build-gsplat` builds it now; training would build it before its first step")
    if env:
        lines.append(f"  build settings: {env}")
    return lines


def _numba_lines() -> list[str]:
    try:
        import numba
        version = numba.__version__
    except ImportError as e:
        return [f"numba    not importable ({e}): the cpu backend is unavailable"]
    try:
        import gsbench.render.cpu_backend  # lazy: optional (numba probe)  # noqa: F401
        state = "the cpu backend imports"
    except ImportError as e:
        state = f"the cpu backend does not import ({e})"
    return [f"numba    {version}, {state}"]


def _auto_lines() -> list[str]:
    lines = ["auto picks (train.device and backend as each preset sets them):"]
    for preset in ["default", *shipped_presets()]:
        cfg = load_config("gaussiands", None if preset == "default" else preset, [])
        want = f"train.device={setting(cfg, 'train.device')}, backend={setting(cfg, 'backend')}"
        try:
            dev = resolve_device(cfg)
            got = f"{dev}, backend {resolve_backend(setting(cfg, 'backend'), dev)}"
        except InputError as e:
            got = f"error: {e}"
        lines.append(f"  {preset:<11} {want:<38} -> {got}")
    return lines


def run(args: argparse.Namespace) -> int:
    if args.build_gsplat:
        build_gsplat_extension()
    for line in _torch_lines() + _gsplat_lines() + _numba_lines() + _auto_lines():
        print(line)
    return 0
