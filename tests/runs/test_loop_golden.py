"""The harness's training loop (gsbench/runs/training.py) reproduces, on a seed, what the methods' own loops
computed before it took them over: every built-in method on the tiny scene, with periodic evaluation,
densification and checkpoints, against tests/data/loop_golden.json (tests/support/loop_golden.py).

Bit for bit, every number: the runs happen in a child process pinned to the kernels every x86-64 CPU
runs alike (loop_golden.PORTABLE_ENV: MKL's COMPATIBLE branch, PyTorch's DEFAULT capability, numba's
generic target, numpy's and OpenCV's baseline kernels), so the file holds on any machine. Without
the pin, MKL's and PyTorch's CPU-chosen kernels move the losses by an ulp within ten steps, and the
thresholded LERF metrics amplify that (loop_golden's docstring has the measurements).

One test for the four methods: the runs take one child process, which a parametrised test would
start once per pytest-xdist worker.
"""
from __future__ import annotations

import json

from loop_golden import golden_runs
from paths import REPO_ROOT

GOLDEN = json.loads((REPO_ROOT / "tests" / "data" / "loop_golden.json").read_text())
# results.json names added after the golden was written: checked by their own tests, not here
ADDED_SINCE = {"ds_edge_fraction"}


def first_difference(got, want, path: str = "") -> str | None:
    """The first path where two JSON trees differ, with both values; None when they are equal."""
    if isinstance(got, dict) and isinstance(want, dict):
        for k in sorted(set(got) | set(want)):
            if k not in got or k not in want:
                return f"{path}/{k}: only in {'golden' if k in want else 'this run'}"
            d = first_difference(got[k], want[k], f"{path}/{k}")
            if d:
                return d
        return None
    if isinstance(got, list) and isinstance(want, list):
        if len(got) != len(want):
            return f"{path}: {len(got)} entries, golden {len(want)}"
        for i, (a, b) in enumerate(zip(got, want)):
            d = first_difference(a, b, f"{path}[{i}]")
            if d:
                return d
        return None
    return None if got == want else f"{path}: {got!r}, golden {want!r}"


def test_metrics_and_training_logs_equal_those_of_the_methods_own_loops(tmp_path):
    runs = golden_runs(tmp_path)
    assert set(runs) == set(GOLDEN)
    diffs = {}
    for method, want in GOLDEN.items():
        got = runs[method]
        assert set(got["metrics"]) - set(want["metrics"]) <= ADDED_SINCE
        metrics = {k: got["metrics"].get(k) for k in want["metrics"]}
        diffs[method] = first_difference({"log": got["log"], "metrics": metrics}, want)
    assert {m: d for m, d in diffs.items() if d} == {}
