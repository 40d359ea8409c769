"""The harness's training loop (gsbench/runs/training.py) reproduces, on a seed, what the methods' own loops
computed before it took them over: every built-in method on the tiny scene, with periodic evaluation,
densification and checkpoints, against tests/data/loop_golden/ (tests/support/loop_golden.py).

- On a CPU family that has a golden file of its own: bit for bit, every number.
- On every x86-64 CPU: the first HORIZON steps of the training log within LOG_RTOL of every family's
  file. The runs happen in a child process pinned to the kernels every x86-64 CPU can be told to run
  alike (loop_golden.PORTABLE_ENV); what is left moves by one float32 ulp across vendors (the module
  docstring of loop_golden and docs/training.md have the measurements).

The runs take one child process for the four methods (a module fixture), which a parametrised test
would start once per pytest-xdist worker.
"""
from __future__ import annotations

import pytest
from loop_golden import (
    HORIZON,
    LOG_RTOL,
    exact_differences,
    family,
    family_file,
    golden_runs,
    goldens,
    within_tolerance,
)

GOLDENS = goldens()


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    return golden_runs(tmp_path_factory.mktemp("golden"))


def test_there_is_a_golden_and_it_names_the_cpu_that_wrote_it():
    assert GOLDENS, "tests/data/loop_golden/ holds no golden file"
    for path, g in GOLDENS.items():
        assert path == family_file(g["written_on"]), f"{path.name} was written on {g['written_on']}"
        assert set(g["runs"]) == {"vanilla", "twostage", "grouping", "gaussiands"}


def test_the_first_steps_agree_with_every_cpu_familys_golden(runs):
    """What any x86-64 CPU must reproduce: the log up to step HORIZON within LOG_RTOL, of every family."""
    diffs = {p.name: d for p, g in GOLDENS.items() if (d := within_tolerance(runs, g["runs"]))}
    assert diffs == {}, f"beyond rtol {LOG_RTOL:g} in the first {HORIZON} steps"


def test_every_bit_equals_the_golden_of_this_cpu_family(runs):
    own = GOLDENS.get(family_file(family()))
    if own is None:
        pytest.skip(f"no golden written on this CPU family ({family()['cpu_model']}, flags "
                    f"{family()['cpu_flags']}): only the first {HORIZON} steps are compared, within rtol "
                    f"{LOG_RTOL:g}; `tests/support/loop_golden.py write --add-family` adds one")
    assert exact_differences(runs, own["runs"]) == {}


@pytest.mark.slow
@pytest.mark.parametrize("mutation", ["adam_beta2", "dssim_weight_ulp"])
def test_a_one_line_change_of_the_loop_is_caught(tmp_path, mutation):
    """An Adam constant (beta2 0.999 -> 0.9995), or L_rec's SSIM weight one float32 ulp higher: both
    comparisons catch both (the ulp in a weight moves every step's gradient, and the periodic PSNR at
    step 10 by about 3e-5 relative, far beyond what another CPU moves). Changes equal in exact
    arithmetic, such as adding two of GaussianDS's loss terms in the other order or L1's mean as a sum
    times 1/n, changed no bit of the tiny runs: the gradient does not depend on the order of the sum."""
    mutated = golden_runs(tmp_path, ("vanilla",), mutation)
    for g in GOLDENS.values():
        want = {"vanilla": g["runs"]["vanilla"]}
        assert set(exact_differences(mutated, want)) == {"vanilla"}
        assert set(within_tolerance(mutated, want)) == {"vanilla"}
