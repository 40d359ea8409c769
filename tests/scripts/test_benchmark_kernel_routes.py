"""benchmarks/kernel_routes.py: every route still applies to the kernels' source, a route that no
longer matches is an error, and a variant compiled from the source runs in the backend's place."""
from __future__ import annotations

import sys

import numpy as np
import pytest
from bench_scripts import load_benchmark
from paths import REPO_ROOT

SOURCE = (REPO_ROOT / "gsbench" / "render" / "cpu_kernels.py").read_text()


@pytest.fixture(scope="module")
def routes():
    sys.path.insert(0, str(REPO_ROOT / "benchmarks"))
    return load_benchmark("kernel_routes")


def test_every_route_applies_to_the_current_kernels(routes):
    for name, (passes, what, subs) in routes.ROUTES.items():
        changed = routes.route_source(SOURCE, subs, name)
        assert changed != SOURCE, name
        assert passes in ("forward", "backward") and what


def test_a_route_that_no_longer_matches_is_an_error(routes):
    with pytest.raises(ValueError, match="route 'gone'.*occurs 0 times"):
        routes.route_source(SOURCE, [("no such line in the kernels", "x", 1)], "gone")
    with pytest.raises(ValueError, match="occurs 1 times in cpu_kernels.py, expected 2"):
        routes.route_source("a b", [("a", "c", 2)], "twice")


def test_same_bits_compares_every_output(routes):
    a = (np.zeros((2, 2), np.float32), np.array([np.nan, 1.0]))
    assert routes.same_bits(a, (a[0].copy(), a[1].copy()))
    assert not routes.same_bits(a, (a[0] + np.float32(1e-7), a[1]))
    assert not routes.same_bits(a, a[:1])


@pytest.mark.slow
def test_a_route_is_compiled_timed_and_checked_on_a_render(routes):
    import render_cpu
    from raster_pairs import capture_renders
    field, cam = render_cpu.make_scene(48, 32, 400, 3, seed=1)
    captured = capture_renders(field, [cam])
    result = routes.measure(captured, ["two channels a loop, forward"], repeats=1, rounds=2, threads=1)
    assert list(result) == ["as is", "two channels a loop, forward"]
    for r in result.values():     # the copy and this route sum each pixel's channels in the same order
        assert r["same_forward"] and r["same_backward"]
        assert len(r["forward"]) == 2 and min(r["forward"]) > 0 and min(r["backward"]) > 0
    assert result["as is"]["ratio_forward"] == [1.0, 1.0]
    assert routes.CB.K is routes.K            # the shipped kernels are back in place
    assert "| two channels a loop, forward | forward |" in routes.table(result)
