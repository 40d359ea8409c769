"""The shipped grids give the report something to put an interval on: every -cpu grid runs at least
three seeds, and the tiny grid that CI runs has two (and stays tiny)."""
from __future__ import annotations

import yaml
from paths import REPO_ROOT

GRIDS = REPO_ROOT / "gsbench" / "grids"


def _seeds(name: str) -> list:
    return yaml.safe_load((GRIDS / name).read_text())["seeds"]


def test_cpu_grids_run_three_seeds():
    cpu = sorted(p.name for p in GRIDS.glob("*-cpu.yaml"))
    assert cpu  # the shipped grids are where this test expects them
    for name in cpu:
        seeds = _seeds(name)
        assert len(set(seeds)) >= 3 and all(isinstance(s, int) for s in seeds), name


def test_tiny_grid_runs_two_seeds_and_stays_tiny():
    g = yaml.safe_load((GRIDS / "tiny-test.yaml").read_text())
    assert sorted(set(g["seeds"])) == [0, 1]
    cells = 1
    for values in g["axes"].values():
        cells *= len(values)
    assert cells * len(g["seeds"]) <= 8 and g["base"]["set"]["train.iterations"] <= 300
