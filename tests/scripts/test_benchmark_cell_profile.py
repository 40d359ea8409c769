"""benchmarks/cell_profile.py: py-spy's samples sorted into a cell's phases."""
from __future__ import annotations

from bench_scripts import load_benchmark

SERVE = "main (multiprocessing/forkserver.py:300);_serve_one (multiprocessing/forkserver.py:340)"


def test_samples_are_sorted_into_phases(tmp_path):
    bench = load_benchmark("cell_profile")
    raw = tmp_path / "raw.txt"
    raw.write_text("\n".join([
        f"process 1:\"python\";{SERVE};run_cell (gsbench/grids/running.py:10);"
        "backward (gsbench/render/cpu_backend.py:252);_raster_backward (gsbench/render/cpu_backend.py:210) 40",
        f"process 1:\"python\";{SERVE};evaluate_run (gsbench/evaluation/run.py:3);"
        "_cosines (gsbench/evaluation/segmentation.py:76);decode (gsbench/train/autoencoder.py:55) 20",
        f"process 1:\"python\";{SERVE};evaluate_run (gsbench/evaluation/run.py:3);"
        "_cosines (gsbench/evaluation/segmentation.py:76) 10",
        "process 2:\"python\";main (multiprocessing/forkserver.py:200);_find_and_load (<frozen>:1) 8",
        f"process 1:\"python\";{SERVE};write_json (gsbench/rundir.py:5) 4",
        "not a sample line",
    ]))
    got = bench.read_raw(raw, rate=40.0)
    assert got == {"raster backward": 1.0, "evaluation: decoder": 0.5,
                   "evaluation: text cosines and pixel norms": 0.25,
                   "forkserver: imports and kernel loading": 0.2, bench.OTHER: 0.1}
