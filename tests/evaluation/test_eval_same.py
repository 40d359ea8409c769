"""benchmarks/eval_same.py: the exact comparison of two evaluations of one run (the end-to-end run
evaluates with two checkouts and is left to the benchmark itself)."""
import json

import numpy as np
from bench_scripts import load_benchmark


def _evaluated(folder, miou, fps, pred):
    (folder / "previews").mkdir(parents=True)
    res = {"run_id": "r", "metrics": {"miou_3dovs": miou, "fps": fps}, "per_view": {"miou_3dovs": [miou]},
           "timings": {"eval_s": fps}, "machine": {"host": str(folder)}}
    (folder / "results.json").write_text(json.dumps(res))
    (folder / "previews" / "previews.json").write_text(json.dumps({"frames": [{"psnr": 20.0}]}))
    np.savez(folder / "previews" / "3dovs_a.npz", pred=np.asarray(pred, np.uint8))


def test_same_results_compare_equal_and_a_changed_bit_is_reported(tmp_path):
    mod = load_benchmark("eval_same")
    _evaluated(tmp_path / "a", 0.5, 10.0, [0, 1])
    _evaluated(tmp_path / "b", 0.5, 99.0, [0, 1])       # timings, machine and the timed fps differ
    assert mod.compare_runs(tmp_path / "a", tmp_path / "b") == []
    _evaluated(tmp_path / "c", np.nextafter(0.5, 1.0), 10.0, [0, 0])
    diffs = mod.compare_runs(tmp_path / "a", tmp_path / "c")
    assert any(d.startswith("results.metrics.miou_3dovs:") for d in diffs)
    assert any(d.startswith("results.per_view.miou_3dovs[0]:") for d in diffs)
    assert "previews/3dovs_a.npz:pred: arrays differ" in diffs
