"""Loading the cpu kernels from numba's cache without calling them (the grid workers' forkserver)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

PROBE = """
import json, sys
import gsbench.render.cpu_backend, gsbench.train.losses_cpu
from gsbench.render import cpu_kernels
from gsbench.render.cached_kernels import cached_dispatchers, load_cached_kernels
before = len(cpu_kernels.raster_forward.signatures)
n = load_cached_kernels()
misses = sum(sum(d.stats.cache_misses.values()) for d in cached_dispatchers(
    [m for k, m in list(sys.modules.items()) if k.startswith("gsbench.") and m is not None]))
print(json.dumps({"before": before, "loaded": n, "after": len(cpu_kernels.raster_forward.signatures),
                  "misses": misses}))
"""


def _probe(env: dict) -> dict:
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_loads_the_cached_kernels_without_compiling():
    """Once a render has put the float32 kernels in the cache, a fresh process loads the cached entries
    (no cache miss, i.e. nothing compiled) before any kernel is called."""
    from pool_jobs import render_once

    from gsbench.render import cpu_kernels
    if not cpu_kernels.raster_forward.stats.cache_path:
        pytest.skip("numba caching is off")
    render_once(0)
    got = _probe(dict(os.environ))
    assert got["before"] == 0
    assert got["loaded"] >= 2 and got["after"] >= 1      # the forward (and the backward, at least)
    assert got["misses"] == 0


def test_nothing_is_loaded_under_a_layer_that_is_not_fork_safe():
    got = _probe({**os.environ, "NUMBA_THREADING_LAYER": "omp"})
    assert got == {"before": 0, "loaded": 0, "after": 0, "misses": 0}


def test_an_unreadable_cache_costs_only_the_preload(monkeypatch, caplog):
    """A cache numba cannot read is logged and skipped: the kernels then load on first call."""
    import logging

    from gsbench.render import cached_kernels, cpu_kernels

    def unreadable(dispatcher):
        raise EOFError("truncated index")

    monkeypatch.setattr(cached_kernels, "_cached_signatures", unreadable)
    with caplog.at_level(logging.INFO, logger="gsbench.render.cached_kernels"):
        assert cached_kernels.load_cached_kernels([cpu_kernels]) == 0
    assert "raster_forward not preloaded (EOFError: truncated index)" in caplog.text
