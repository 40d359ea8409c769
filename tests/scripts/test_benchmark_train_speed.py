"""benchmarks/train_speed.py runs end to end (a smoke test: rows and ratios present, no timing asserted)."""
import json

import pytest
from bench_scripts import load_benchmark


@pytest.mark.slow
def test_train_speed_prints_rows_and_writes_json(tmp_path, capsys):
    mod = load_benchmark("train_speed")
    assert mod.main(["--sizes", "300@32x24", "--iters", "5", "--devices", "cpu",
                     "--json", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    rows = json.loads((tmp_path / "r.json").read_text())["rows"]
    assert [r["row"] for r in rows] == ["bare cpu-backend step", "vanilla", "gaussiands"]
    assert all(r["its"] > 0 for r in rows) and rows[2]["ratio_vanilla"] > 0
    assert out.count("| cpu | 300 | 32x24 |") == 3 + 2       # 3 speed rows, 2 phase rows
    for r in rows[1:]:          # the phase timers are wired: the renderer's phases took time
        ph = r["phases_ms"]
        assert set(ph) == {"projection", "raster fwd", "raster bwd", "losses", "optimiser", "densify", "other"}
        assert ph["raster fwd"] > 0 and ph["raster bwd"] > 0 and ph["projection"] > 0 and ph["optimiser"] > 0
