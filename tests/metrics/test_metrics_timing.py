"""FPS timer: warm-up, sync around each call, median."""
from __future__ import annotations

import time

import pytest

from gsbench.metrics import time_fps


def test_counts_sync_and_median():
    calls = []
    syncs = []

    def fn():
        calls.append(1)

    def my_sync():
        syncs.append(1)

    out = time_fps(fn, warmup=3, repeats=5, sync=my_sync)
    assert len(calls) == 8
    assert len(syncs) == 1 + 5                       # once after warm-up, once per timed call
    assert out["sync"].endswith("my_sync")
    assert len(out["times_ms"]) == 5
    assert out["median_ms"] == sorted(out["times_ms"])[2]
    assert out["fps"] == pytest.approx(1000.0 / out["median_ms"])


def test_measures_real_time():
    out = time_fps(lambda: time.sleep(0.004), warmup=1, repeats=3)
    assert out["median_ms"] >= 4.0
    assert out["fps"] <= 250.0
    assert out["sync"].startswith("none")           # CPU-only test machine: no device sync


def test_bad_arguments():
    with pytest.raises(ValueError):
        time_fps(lambda: None, repeats=0)
