"""`gsbench stress`: the battery runs, reports one row per case, and a failing case fails the command."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import torch

from gsbench import stress
from gsbench.cli import main
from gsbench.commands.hostile import hostile_cases

REQUIRED_COMPONENTS = ["render:torch", "projection", "depth-solve", "loss:rec", "loss:depth", "loss:tv", "loss:sem",
                       "loss:ds", "stiff-lambdas", "autoencoder", "metrics"]


def test_battery_lists_every_component_and_required_case(capsys):
    assert main(["stress", "--list"]) == 0
    lines = [ln.split("\t") for ln in capsys.readouterr().out.splitlines() if "\t" in ln]
    comps = {c for c, _ in lines}
    for comp in REQUIRED_COMPONENTS:
        assert comp in comps, comp
    names = {(c, n) for c, n in lines}
    for n in ["scale 1e-06 x scene", "scale 1000 x scene", "aspect ratio 1e4", "behind the camera (z=-1)",
              "opacity 0", "opacity 1", "zero quaternions", "1x1 image", "single Gaussian", "100k Gaussians"]:
        assert ("render:torch", n) in names, n
    for n in ["constant prior", "all-NaN prior", "all-inf prior", "negative prior", "all-invalid prior",
              "huge magnitudes (1e6)"]:
        assert ("depth-solve", n) in names, n
    assert ("loss:tv", "zero gradient (constant depth)") in names
    assert ("loss:ds", "empty edge map") in names
    assert ("stiff-lambdas", "all lambdas 0.0001") in names and ("stiff-lambdas", "all lambdas 10000") in names
    # nothing is skipped as "not importable" in this build
    _, skipped = stress.all_cases()
    assert skipped == []


def test_subset_runs_in_process_and_passes():
    cases, skipped = stress.all_cases(["depth-solve", "loss:tv", "loss:ds", "metrics", "autoencoder"])
    assert not skipped and len(cases) >= 30
    rows = [stress.run_case(c).row() for c in cases]
    failed = [(r["component"], r["case"], r["note"]) for r in rows if not r["pass"]]
    assert failed == []
    for r in rows:
        assert set(r) >= {"component", "case", "max_abs", "max_rel", "finite_out", "finite_grad", "pass", "note"}
        assert r["finite_out"] is True


def test_cli_writes_csv_and_exits_zero(tmp_path, capsys):
    code = main(["stress", "--component", "loss:tv", "--component", "depth-solve", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0
    df = pd.read_csv(tmp_path / "stress.csv")
    assert len(df) >= 15 and df["pass"].all()
    assert set(df["component"]) == {"loss:tv", "depth-solve"}
    assert "0 failed" in out and "| component" in out
    assert (tmp_path / "stress.md").read_text().startswith("| component")


def _broken_cases() -> list[stress.Case]:
    def wrong_reference() -> stress.CaseResult:
        # float32 output deliberately compared with a reference that is off by 1e-2
        x = torch.linspace(0, 1, 10)
        return stress._result("broken", [x], [x.double() + 1e-2], None, None, out_tol=1e-4)

    def nan_output() -> stress.CaseResult:
        x = torch.tensor([1.0, float("nan")])
        return stress._result("broken", [x], [x.double()], None, None, out_tol=1.0)

    def nan_gradient() -> stress.CaseResult:
        x = torch.zeros(3, requires_grad=True)
        y = torch.sqrt(x).sum()          # d sqrt(x) / dx at 0 = inf
        g = torch.autograd.grad(y, x)[0]
        return stress._result("broken", [y], [y.double()], [g], [g.double()], out_tol=1.0)

    def crash() -> stress.CaseResult:
        raise RuntimeError("boom")

    return [stress.Case("broken", "wrong reference", wrong_reference), stress.Case("broken", "NaN output", nan_output),
            stress.Case("broken", "non-finite gradient", nan_gradient), stress.Case("broken", "crash", crash)]


def test_broken_cases_fail_and_exit_one(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(stress, "_EXTRA_CASE_LOADERS", stress._EXTRA_CASE_LOADERS + [_broken_cases])
    code = main(["stress", "--component", "broken", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 1
    df = pd.read_csv(tmp_path / "stress.csv")
    assert list(df["case"]) == ["wrong reference", "NaN output", "non-finite gradient", "crash"]
    assert not df["pass"].any()
    row = df.set_index("case")
    assert math.isclose(row.loc["wrong reference", "max_abs"], 1e-2, rel_tol=1e-3)
    assert not row.loc["NaN output", "finite_out"]
    assert not row.loc["non-finite gradient", "finite_grad"]
    assert "crashed: RuntimeError: boom" in row.loc["crash", "note"]
    assert "4 failed" in out and "FAIL" in out


def test_unimportable_component_is_a_failed_row(monkeypatch, capsys):
    def missing_cases():
        raise ImportError("No module named 'gsbench.nothing'")

    monkeypatch.setattr(stress, "_EXTRA_CASE_LOADERS", stress._EXTRA_CASE_LOADERS + [missing_cases])
    code = main(["stress", "--component", "missing"])
    out = capsys.readouterr().out
    assert code == 1
    assert "not importable" in out and "FAIL" in out


def test_comparison_helpers_detect_errors():
    # hand-computed: |[1, 2.5] - [1, 2]| max 0.5; relative to 2 -> 0.25
    a, r = stress.compare(np.array([1.0, 2.5]), np.array([1.0, 2.0]))
    assert a == pytest.approx(0.5) and r == pytest.approx(0.25)
    assert stress.scaled_err(np.array([0.0, 3.0]), np.array([0.0, 4.0])) == pytest.approx(0.25)
    assert stress.scaled_err(np.array([np.nan]), np.array([1.0])) == math.inf
    assert not stress.all_finite(torch.tensor([0.0, float("inf")]))
    assert stress.all_finite(np.zeros(3), None)


@pytest.mark.slow
def test_full_battery_passes_via_the_executable(tmp_path):
    """CI runs the whole `gsbench stress` (every backend present, every component): exit 0, one CSV row per case."""
    import subprocess
    import sys
    from pathlib import Path

    exe = Path(sys.executable).parent / "gsbench"
    proc = subprocess.run([str(exe), "stress", "--out", str(tmp_path)], capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stdout[-4000:]
    df = pd.read_csv(tmp_path / "stress.csv")
    cases, skipped = stress.all_cases()
    hostile = hostile_cases()
    assert len(df) == len(cases) + len(hostile) + len(skipped) and not skipped
    assert df["pass"].all()
    assert set(REQUIRED_COMPONENTS) <= set(df["component"])
    hostile_areas = {f"hostile:{a}" for a in ("config", "data", "eval", "output", "store")}
    assert hostile_areas <= set(df["component"])
    assert {c.component for c in hostile} == hostile_areas     # a new area is named here too
