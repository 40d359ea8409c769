"""The harness's training loop (gsbench/runs/training.py) reproduces, on a seed, what the methods' own loops
computed before it took them over: every built-in method on the tiny scene, with periodic evaluation,
densification and checkpoints, against tests/data/loop_golden.json (tests/support/loop_golden.py)."""
from __future__ import annotations

import json

import pytest
from loop_golden import golden_runs
from paths import REPO_ROOT

GOLDEN = json.loads((REPO_ROOT / "tests" / "data" / "loop_golden.json").read_text())
# results.json names added after the golden was written: checked by their own tests, not here
ADDED_SINCE = {"ds_edge_fraction"}


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict:
    return golden_runs(tmp_path_factory.mktemp("loop_golden"))


@pytest.mark.parametrize("method", sorted(GOLDEN))
def test_metrics_and_training_log_equal_those_of_the_methods_own_loops(runs, method):
    assert runs[method]["log"] == GOLDEN[method]["log"]
    got, want = runs[method]["metrics"], GOLDEN[method]["metrics"]
    assert set(got) - set(want) <= ADDED_SINCE and set(want) <= set(got)
    assert {k: got[k] for k in want} == want
