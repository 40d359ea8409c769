"""Session-wide fixtures: one tiny generated scene and one trained tiny run, built once per test
session and shared read-only (a test that changes them works on a copy)."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

# `python -m pytest` puts the working directory first on sys.path; from the repository root that would
# let its top-level folders import by bare name (`datasets` shadowing Hugging Face's) and bypass the
# installed package. The suite imports gsbench.* only (importlib mode), so the root is taken off.
_ROOT = Path(__file__).resolve().parent.parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _ROOT]

from tiny import TINY_SCENE_ARGS, TINY_TRAIN_ARGS  # noqa: E402

from gsbench.cli import main  # noqa: E402


def _share_the_cores_between_xdist_workers() -> None:
    """Under pytest-xdist (`make test` runs one worker per core), each worker and the processes it
    starts get cores // workers threads: two workers of two OpenMP threads each on two cores spin
    against each other (a torch render test ran 18x slower)."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT") or 0)
    if workers < 2:
        return
    n = str(max(1, len(os.sched_getaffinity(0)) // workers))
    for key in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "GSBENCH_THREADS"):
        os.environ[key] = n
    import torch  # lazy: only the thread count is set here

    torch.set_num_threads(int(n))


_share_the_cores_between_xdist_workers()


def pytest_configure(config) -> None:
    """In the xdist controller, before the workers start: compile the numba kernels into numba's
    cache, float32 and float64 side by side (tests/support/numba_warmup.py), and on a CUDA machine
    with gsplat its CUDA extension, so the workers do not each compile them at once on a fresh clone
    (gsplat clears its build folder when it finds no finished build: on an H200 with 14 workers,
    each compiling, the gsplat tests failed with a missing gsplat_cuda.so). GSBENCH_TEST_WARMUP=0
    turns it off."""
    if hasattr(config, "workerinput") or not config.getoption("numprocesses", None):
        return
    if os.environ.get("GSBENCH_TEST_WARMUP") == "0":
        return
    script = Path(__file__).parent / "support" / "numba_warmup.py"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "GSBENCH_THREADS": "1"}
    procs = [subprocess.Popen([sys.executable, str(script), dtype], env=env) for dtype in ("float32", "float64")]
    if importlib.util.find_spec("gsplat") is not None:
        procs.append(subprocess.Popen([sys.executable, "-c", _BUILD_GSPLAT]))
    for p in procs:
        p.wait()   # a failure here shows again, with its test, in the tests that render


# the one-time build of gsplat's CUDA extension where it can render (gsbench doctor --build-gsplat's call)
_BUILD_GSPLAT = """
import torch
from gsbench.render.gsplat_ext import NEEDS_BUILD, build_gsplat_extension, gsplat_status
if torch.cuda.is_available() and gsplat_status().state == NEEDS_BUILD:
    build_gsplat_extension()
"""


@pytest.fixture(scope="session")
def tiny_scene(tmp_path_factory) -> Path:
    """A generated scene folder (3D-OVS + LERF layouts, GT depth, sparse points). Do not modify it."""
    out = tmp_path_factory.mktemp("tiny_scene") / "tabletop"
    assert main(["make-scene", *TINY_SCENE_ARGS, "--out", str(out), "--quiet"]) == 0
    return out


@pytest.fixture(scope="session")
def tiny_run(tiny_scene, tmp_path_factory) -> Path:
    """A finished vanilla run folder trained on `tiny_scene`. Do not modify it."""
    run = tmp_path_factory.mktemp("tiny_runs") / "vanilla"
    assert main(["train", *TINY_TRAIN_ARGS, "--scene", str(tiny_scene), "--out", str(run)]) == 0
    return run
