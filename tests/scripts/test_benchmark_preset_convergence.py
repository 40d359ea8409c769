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
