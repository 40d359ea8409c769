"""benchmarks/preset_convergence.py: the long run is the preset with every step count times the factor."""
from __future__ import annotations

import yaml
from bench_scripts import load_benchmark
from paths import REPO_ROOT


def test_the_long_schedule_multiplies_every_step_count_of_the_preset():
    bench = load_benchmark("preset_convergence")
    preset = yaml.safe_load((REPO_ROOT / "gsbench" / "configs" / "cpu-medium.yaml").read_text())["train"]
    got = dict(s.split("=") for s in bench.scaled_schedule("vanilla", "cpu-medium", 4, []))
    assert got["train.iterations"] == str(4 * preset["iterations"])
    assert got["train.lr.position_max_steps"] == str(4 * preset["lr"]["position_max_steps"])
    for key in ("from_iter", "until_iter", "interval", "opacity_reset_interval"):
        assert got[f"train.densify.{key}"] == str(4 * preset["densify"][key])
    # cpu-medium's four-times schedule is cpu-real's
    real = yaml.safe_load((REPO_ROOT / "gsbench" / "configs" / "cpu-real.yaml").read_text())["train"]
    assert got["train.iterations"] == str(real["iterations"])
    assert got["train.densify.until_iter"] == str(real["densify"]["until_iter"])
    # overrides are scaled too: a preset set shorter on the command line gives a long run four times that
    got = dict(s.split("=") for s in bench.scaled_schedule("vanilla", "cpu-medium", 4, ["train.iterations=100"]))
    assert got["train.iterations"] == "400"


def test_the_plot_joins_each_preset_to_its_long_run_and_says_which_converged(tmp_path):
    bench = load_benchmark("preset_convergence")
    rows = [{"preset": "a.yaml", "iterations": 100, "psnr": 20.0, "train_s": 10.0},
            {"preset": "a.yaml", "iterations": 400, "psnr": 20.4, "train_s": 40.0},
            {"preset": "cpu-b", "iterations": 200, "psnr": 21.0, "train_s": 20.0},
            {"preset": "cpu-b", "iterations": 800, "psnr": 22.5, "train_s": 80.0}]
    out = tmp_path / "plot.png"
    labels = bench.plot_rows(rows, 4, "test", out)
    assert labels == ["a: 100 steps, gap +0.40 dB (converged)", "cpu-b: 200 steps, gap +1.50 dB (not converged)"]
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
