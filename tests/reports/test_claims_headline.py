"""The headline claim rows (issue 54): GaussianDS against each method at its defaults, read from the
`reconstruction` study; the FPS row as a ratio with an equivalence margin (statsmodels' ttost_paired
on the logs as the reference), a metric the runs could not compute as "not measured" with its reason,
and a timing that no control guards."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from report_runs import write_run
from scipy import stats as sps
from statsmodels.stats.weightstats import ttost_paired

from gsbench.collect import collect
from gsbench.methods.gaussiands.study_table import FPS_MARGIN, paper_claims
from gsbench.reports.claims_table import NOT_MEASURED, REPRODUCED, claim_rows
from gsbench.reports.data import Results

FPS_GDS = [6.10, 5.80, 6.40, 6.00]
FPS_VAN = [6.30, 6.20, 6.35, 6.25]
PSNR_GDS = [25.0, 25.9, 25.5, 25.2]
PSNR_VAN = [27.2, 27.3, 27.1, 27.0]


def _headline_runs(root: Path) -> None:
    for seed in range(4):
        write_run(root, f"rec/gds{seed}", method="gaussiands", scene="bench", seed=seed, study="reconstruction",
                  grid={"method": "gaussiands"}, skipped={"lpips": "no LPIPS weights: vgg16 not found"},
                  metrics={"psnr": PSNR_GDS[seed], "fps": FPS_GDS[seed], "lpips": None},
                  timings={"train_s": 90.0, "eval_s": 9.0, "fps": FPS_GDS[seed]})
        write_run(root, f"rec/van{seed}", method="vanilla", scene="bench", seed=seed, study="reconstruction",
                  grid={"method": "vanilla"}, skipped={"lpips": "no LPIPS weights: vgg16 not found"},
                  metrics={"psnr": PSNR_VAN[seed], "fps": FPS_VAN[seed], "lpips": None},
                  timings={"train_s": 60.0, "eval_s": 5.0, "fps": FPS_VAN[seed]})


def _rows(root: Path) -> dict:
    return {r.claim.key: r for r in claim_rows(Results(collect(root)), paper_claims()) if r.measured is not None}


def test_fps_is_a_ratio_decided_by_tost_on_the_logs(tmp_path: Path):
    _headline_runs(tmp_path)
    row = _rows(tmp_path)["rec_fps_vanilla"]
    a, b = np.log(FPS_GDS), np.log(FPS_VAN)
    d = a - b
    se = d.std(ddof=1) / math.sqrt(d.size)
    lo, hi = sps.t.interval(0.95, d.size - 1, loc=d.mean(), scale=se)
    text = row.measured.text
    assert text.startswith(f"ratio {math.exp(d.mean()):.2f} [{math.exp(lo):.2f}, {math.exp(hi):.2f}]"), text
    p, _lower, _upper = ttost_paired(a, b, -FPS_MARGIN, FPS_MARGIN)
    assert p < 0.05   # by hand: the ratios 0.97, 0.94, 1.01, 0.96 lie well inside 0.80 to 1.25
    assert row.measured.verdict == REPRODUCED
    assert row.measured.p == pytest.approx(p, rel=1e-9)
    lo90, hi90 = sps.t.interval(0.90, d.size - 1, loc=d.mean(), scale=se)
    assert f"90 % [{math.exp(lo90):.2f}, {math.exp(hi90):.2f}] against 0.80 to 1.25" in text
    # a timing: no control guards it, and no missing control blinds it
    assert row.guard.text.startswith("none needed") and row.guard.blind is None


def test_a_metric_the_runs_could_not_compute_reads_not_measured_with_its_reason(tmp_path: Path):
    _headline_runs(tmp_path)
    row = _rows(tmp_path)["rec_lpips_vanilla"]
    assert row.measured.verdict == f"{NOT_MEASURED}: no LPIPS weights"
    assert "no LPIPS weights" in row.measured.text
    assert row.measured.p is None   # nothing tested: not in the Holm family


def test_psnr_row_compares_gaussiands_with_vanilla_paired_on_seeds(tmp_path: Path):
    _headline_runs(tmp_path)
    row = _rows(tmp_path)["rec_psnr_vanilla"]
    d = np.subtract(PSNR_GDS, PSNR_VAN)
    se = d.std(ddof=1) / math.sqrt(d.size)
    lo, hi = sps.t.interval(0.95, d.size - 1, loc=d.mean(), scale=se)
    assert row.measured.text.startswith(f"{d.mean():+.2f} [{lo:+.2f}, {hi:+.2f}] * (n=4, paired)")
    assert row.measured.verdict.startswith("opposite")   # the interval lies wholly below zero
    # the paper credits the colour to the depth prior: control_depth guards it, here not run
    assert "control_depth" in row.guard.text or "none" in row.guard.text


def test_every_headline_row_names_its_table_and_the_methods_it_compares():
    rows = [c for c in paper_claims() if c.study == "reconstruction"]
    assert len(rows) == 14
    assert {c.reference["method"] for c in rows} == {"vanilla", "grouping", "twostage"}
    assert all(c.row == {"method": "gaussiands"} for c in rows)
    assert all(("tab-" in c.source) or ("fig-" in c.source) for c in rows)
    # the paper's numbers as printed: bench PSNR 24.81 against 16.02 (vanilla) and 18.71 (Grouping)
    by_key = {c.key: c for c in rows}
    assert by_key["rec_psnr_vanilla"].paper == pytest.approx(8.79)
    assert by_key["rec_psnr_grouping"].paper == pytest.approx(6.10)
    assert by_key["seg_lerf_twostage"].paper == pytest.approx(9.1) and by_key["seg_lerf_twostage"].paper_decimals == 1
