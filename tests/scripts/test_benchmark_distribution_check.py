"""benchmarks/distribution_check.py: per arm and metric, the baseline's mean and 95 % t-interval over
the seeds, the head's mean and their difference; equal cells counted; the published store compared."""
from __future__ import annotations

import json
import math

import pytest
from bench_scripts import load_benchmark


def _cells(values: dict[str, list[float]], shift: float = 0.0) -> dict:
    out = {}
    for arm, vals in values.items():
        for seed, v in enumerate(vals):
            out[f"{arm}-{seed}"] = {"arm": arm, "seed": seed, "metrics": {"psnr": v + shift, "lpips_package": "x"}}
    return out


def test_same_bits_give_zero_differences_inside_every_interval():
    bench = load_benchmark("distribution_check")
    base = _cells({"a": [20.0, 21.0, 22.0, 20.5, 21.5], "b": [10.0, 10.0, 10.0, 10.0, 10.0]})
    rows, same, total = bench.compare(base, base, ["psnr", "lpips_package", "missing"])
    assert (same, total) == (10, 10)
    assert [r["arm"] for r in rows] == ["a", "b"] and all(r["diff"] == 0 and r["inside"] for r in rows)
    a = rows[0]
    # mean 21.0, sd 0.790569..., t(0.975, 4) = 2.776445...: half width 0.98163...
    assert a["base_mean"] == pytest.approx(21.0)
    assert a["hi"] - a["base_mean"] == pytest.approx(2.7764451 * math.sqrt(0.625) / math.sqrt(5), rel=1e-6)


def test_a_shift_beyond_the_interval_is_flagged():
    bench = load_benchmark("distribution_check")
    base = _cells({"a": [20.0, 21.0, 22.0, 20.5, 21.5]})
    rows, same, total = bench.compare(base, _cells({"a": [20.0, 21.0, 22.0, 20.5, 21.5]}, shift=1.5), ["psnr"])
    assert (same, total) == (0, 5)
    assert rows[0]["diff"] == pytest.approx(1.5) and not rows[0]["inside"]
    rows, _, _ = bench.compare(base, _cells({"a": [20.0, 21.0, 22.0, 20.5, 21.5]}, shift=0.5), ["psnr"])
    assert rows[0]["inside"]


def test_head_cells_are_compared_with_the_published_store(tmp_path):
    bench = load_benchmark("distribution_check")
    (tmp_path / "g").mkdir()
    for run_id, v in (("a-0", 20.0), ("a-1", 99.0)):
        (tmp_path / "g" / f"{run_id}.json").write_text(json.dumps({"results": {"metrics": {"psnr": v}}}))
    head = _cells({"a": [20.0, 21.0, 22.0]})
    assert bench.against_store(head, tmp_path, ["psnr"]) == (1, 2)   # a-2 is not in the store
