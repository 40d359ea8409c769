"""Memory per run: a run's peaks are its own, not those of an earlier run in the same process or grid."""
from __future__ import annotations

import numpy as np
import pytest

from gsbench.environment import RSS_RESET, PeakMemory, env_info, lifetime_peak_rss_mb
from gsbench.store import read_json

MB = 2**20


def test_peak_memory_is_reset_per_phase():
    with PeakMemory() as big:
        a = np.ones(400 * MB // 8)            # 400 MB touched
        a[::4096] += 1.0
        big_peak = big.read()
        del a
    if big_peak["rss_source"] != RSS_RESET:
        pytest.skip("this kernel does not let a process reset its peak RSS (/proc/self/clear_refs)")
    with PeakMemory() as small:
        b = np.ones(10 * MB // 8)
        b[::4096] += 1.0
        small_peak = small.read()
    assert big_peak["peak_rss_mb"] - small_peak["peak_rss_mb"] > 300
    # Linux derives ru_maxrss from the same counter, so the reset also stops it reporting the big phase
    assert lifetime_peak_rss_mb() < big_peak["peak_rss_mb"] - 300
    assert "peak_cuda_mb" not in small_peak                           # a CPU phase has no CUDA figure


@pytest.mark.cuda
def test_cuda_peak_is_reset_per_phase():
    torch = pytest.importorskip("torch")
    if not torch.cuda.is_available():
        pytest.skip("no CUDA device")
    with PeakMemory("cuda") as big:
        x = torch.ones(256 * MB // 4, device="cuda")
        big_peak = big.read()
        del x
    with PeakMemory("cuda") as small:
        y = torch.ones(MB // 4, device="cuda")
        small_peak = small.read()
        del y
    assert big_peak["peak_cuda_mb"] >= 256 and small_peak["peak_cuda_mb"] < 64


def test_env_info_has_the_fields_results_compare_by():
    e = env_info()
    for k in ("host", "cpu", "cores", "python", "torch", "numpy", "torch_threads", "cuda", "gsbench", "git_sha"):
        assert k in e
    assert e["cores"] >= 1 and e["torch_threads"] >= 1


GRID = """study: memory-test
base:
  method: vanilla
  preset: cpu-small
  set:
    train.iterations: 2
    train.init.mode: random
    train.densify.enabled: false
    train.densify.max_gaussians: 1000000
    train.eval_every: 0
    eval.fps_warmup: 0        # the peaks come from holding and rendering the Gaussians, not from timing them
    eval.fps_repeats: 1
    eval.previews: 0
scenes: [{preset: tabletop-small, views: 6, resolution: [32, 24]}]
seeds: [0]
axes:
  train.init.num_random: [1000000, 1000]    # the big cell runs first; big enough to stand >100 MB above the small one
"""


def _memory_by_size(runs) -> dict:
    out = {}
    for p in runs.glob("*/results.json"):
        r = read_json(p)
        out[r["config"]["train"]["init"]["num_random"]] = r["memory"]
    return out


@pytest.mark.slow
@pytest.mark.parametrize("executor", ["local", "serial"])
def test_grid_cells_do_not_inherit_an_earlier_cells_memory(tmp_path, executor):
    """A big cell then a small cell in one grid: the small cell's train peak is its own. With the local
    executor (one fresh process per cell) its evaluation peak is its own too."""
    from gsbench import grids
    from gsbench.grids.executors import make_executor
    (tmp_path / "g.yaml").write_text(GRID)
    grid = grids.load_grid(tmp_path / "g.yaml")
    rep = grids.run_grid(grid, tmp_path / "runs", make_executor(executor, jobs=1, progress=False),
                         log=lambda s: None)
    assert [r["state"] for r in rep.results] == ["done", "done"]
    mem = _memory_by_size(tmp_path / "runs")
    big, small = mem[1000000], mem[1000]
    sources = {read_json(p)["rss_source"] for p in (tmp_path / "runs").glob("*/train_summary.json")}
    if executor == "serial" and sources != {RSS_RESET}:
        pytest.skip("in one process the per-run figure needs /proc/self/clear_refs, which this kernel refuses")
    assert big["train_peak_rss_mb"] - small["train_peak_rss_mb"] > 100, mem
    if executor == "local":
        assert big["peak_rss_mb"] - small["peak_rss_mb"] > 100, mem
    assert sources <= {RSS_RESET, "ru_maxrss (process lifetime)"}
