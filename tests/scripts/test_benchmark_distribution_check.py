"""benchmarks/distribution_check.py: per arm and metric, the baseline's mean and 95 % t-interval over
the seeds, the head's mean and their difference; equal cells counted; the published store compared."""
from __future__ import annotations

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


def test_the_head_is_set_against_the_published_seeds_of_each_setting():
    """Against the repository's own store: a head whose cells are the store's control_sem cells has
    each arm's mean equal to the store's, inside its interval; shifted by 5 dB it falls outside. Value
    for value only the cells of this machine's CPU family are compared."""
    from paths import REPO_ROOT

    from gsbench.environment import cpu_facts
    from gsbench.grids.store import read_store
    from gsbench.grids.verify import same_cpu
    bench = load_benchmark("distribution_check")
    store = REPO_ROOT / "results" / "cpu"
    cells = [c for c in read_store(store) if c.grid == "control_sem-cpu"]
    assert len(cells) >= 4
    head = {c.run_id: {"arm": f"sem={c.record['cell']['axes']}", "seed": c.record["cell"]["seed"],
                       "metrics": dict(c.metrics)} for c in cells}
    rows, same, total = bench.against_store(head, store, ["psnr", "miou_3dovs"])
    assert len(rows) == 4 and all(r["diff"] == 0 and r["inside"] for r in rows)
    family = sum(same_cpu(c.record["provenance"], cpu_facts()) for c in cells)
    assert (same, total) == (2 * family, 2 * family)
    for c in head.values():
        c["metrics"]["psnr"] += 5.0
    rows, _, _ = bench.against_store(head, store, ["psnr"])
    assert all(r["diff"] == pytest.approx(5.0) and not r["inside"] for r in rows)
