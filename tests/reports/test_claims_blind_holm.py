"""Positive controls marked by Holm across their rows (statsmodels multipletests as the reference, and
a no-effect simulation of the 12-row depth-noise control), blind verdicts for every claim kind whose
interval includes zero, the paper's numbers at the paper's decimals, and the family-wise captions."""
from __future__ import annotations

import gc
import re
from pathlib import Path

import numpy as np
import pytest
from report_runs import write_run
from statsmodels.stats.multitest import multipletests

from gsbench.collect import collect
from gsbench.reports.claims_table import (
    INCONCLUSIVE,
    PAPER_CLAIMS,
    REPRODUCED,
    SMALLER,
    claims_table,
    verdict,
    verdict_text,
)
from gsbench.reports.controls import MARKED, NOT_RUN, OPPOSITE, UNMARKED, controls_table, mark_rows
from gsbench.reports.data import Results
from gsbench.reports.stats import compare

KINDS = ("gaussian", "poisson", "salt_pepper", "motion_blur")
SEVERITIES = (1, 3, 5)
SEED_NOISE = [0.0, 0.3, -0.2]


@pytest.fixture
def no_gc_in_multipletests(monkeypatch):
    """statsmodels' Holm runs gc.collect() on every call (about 0.3 s each here); it changes no result."""
    monkeypatch.setattr(gc, "collect", lambda *args: 0)


def test_mark_rows_follow_statsmodels_holm(no_gc_in_multipletests):
    rng = np.random.default_rng(11)
    for _ in range(30):
        diffs = []
        for _row in range(6):
            ref = rng.normal(20.0, 1.0, 3)
            diffs.append(compare(dict(enumerate(ref + rng.normal(rng.choice([-2.0, 0.0, 1.0]), 0.4, 3))),
                                 dict(enumerate(ref))))
        marks = mark_rows(diffs, -1)
        reject, corrected, _, _ = multipletests([d.p for d in diffs], alpha=0.05, method="holm")
        for d, (mark, holm_p), rej, q in zip(diffs, marks, reject, corrected):
            assert holm_p == pytest.approx(q, abs=1e-12)
            assert mark == (UNMARKED if not rej else MARKED if d.delta < 0 else OPPOSITE)
    # a row that did not run or has one seed is not part of the family
    one_seed, strong = compare({0: 1.0}, {0: 2.0}), compare({0: 1.0, 1: 1.1, 2: 0.9}, {0: 3.0, 1: 3.0, 2: 3.0})
    assert mark_rows([None, one_seed, strong], -1) == [(NOT_RUN, None), (UNMARKED, None), (MARKED, strong.p)]


def _old_rule_marks(diffs, direction) -> bool:
    """The rule before Holm: any row's interval excludes zero on the expected side."""
    return any(d.significant and (d.delta > 0) == (direction > 0) for d in diffs)


def test_holm_keeps_false_marking_at_or_under_five_percent():
    """No true effect, 12 rows against one shared reference, 3 seeds, seed noise shared by all rows:
    the old rule marks the control about one time in five; Holm at most one time in twenty."""
    rng = np.random.default_rng(2024)
    draws, old, new = 300, 0, 0
    for _ in range(draws):
        seed_noise = rng.normal(0.0, 1.0, 3)
        ref = dict(enumerate(20.0 + seed_noise + rng.normal(0.0, 0.3, 3)))
        diffs = [compare(dict(enumerate(20.0 + seed_noise + rng.normal(0.0, 0.3, 3))), ref) for _ in range(12)]
        old += _old_rule_marks(diffs, -1)
        new += any(m == MARKED for m, _ in mark_rows(diffs, -1))
    assert old / draws > 0.12   # the simulation reproduces the false marking
    assert new / draws <= 0.05


def _control_noise_runs(root: Path, strong: list[float]) -> None:
    """control_depth_noise: 12 rows against the clean prior; every row but motion blur at severity 5
    moves by +-0.3 dB around zero; that one by `strong` (per seed)."""
    for s in range(3):
        write_run(root, f"cdn/clean_{s}", method="gaussiands", scene="bench", seed=s, study="control_depth_noise",
                  grid={"priors.depth.noise.type": None, "priors.depth.noise.severity": 0},
                  metrics={"psnr": 22.0 + SEED_NOISE[s]})
        for kind in KINDS:
            for sev in SEVERITIES:
                move = strong[s] if (kind, sev) == ("motion_blur", 5) else 0.3 * (-1) ** (s + sev)
                write_run(root, f"cdn/{kind}{sev}_{s}", method="gaussiands", scene="bench", seed=s,
                          study="control_depth_noise",
                          grid={"priors.depth.noise.type": kind, "priors.depth.noise.severity": sev},
                          metrics={"psnr": 22.0 + SEED_NOISE[s] + move})


def _noise_claim_runs(root: Path, drops: dict[str, list[float]]) -> None:
    """depth_noise study: the clean prior and, per kind, severity 5 lowered by drops[kind] per seed."""
    for s in range(3):
        write_run(root, f"dn/clean_{s}", method="gaussiands", scene="bench", seed=s, study="depth_noise",
                  grid={"priors.depth.noise.type": None, "priors.depth.noise.severity": 0},
                  metrics={"psnr": 24.0 + SEED_NOISE[s]})
        for kind, drop in drops.items():
            write_run(root, f"dn/{kind}_{s}", method="gaussiands", scene="bench", seed=s, study="depth_noise",
                      grid={"priors.depth.noise.type": kind, "priors.depth.noise.severity": 5},
                      metrics={"psnr": 24.0 + SEED_NOISE[s] - drop[s]})


def _psnr_noise_row(row) -> bool:
    """A row of the depth-noise PSNR control (the same study also has the depth-error control)."""
    return row.labels[1].startswith("control_depth_noise") and row.labels[0].endswith("lowers PSNR")


def _verdicts(res: Results) -> dict[str, str]:
    t = claims_table(res)[0]
    texts = {c.text: c.key for c in PAPER_CLAIMS}
    return {texts[r.labels[0]]: r.cells[3].plain() for r in t.rows}


DROPS = {
    "gaussian": [0.1, -0.1, 0.05],        # -0.02 [-0.27, +0.23]: inside the margin, includes zero
    "poisson": [0.47, 0.45, 0.49],        # -0.47 [-0.52, -0.42]: crosses the margin, excludes zero
    "salt_pepper": [0.2, 0.21, 0.19],     # -0.20 [-0.22, -0.18]: inside the margin, excludes zero
}


def test_a_row_that_fails_holm_leaves_the_control_unmarked_and_the_claims_blind(tmp_path: Path):
    # motion blur 5: -1.0, -1.2, -0.9 dB: its own interval excludes zero (p ~ 0.007), but 12 x 0.007 > 0.05
    _control_noise_runs(tmp_path, [-1.0, -1.2, -0.9])
    _noise_claim_runs(tmp_path, DROPS)
    res = Results(collect(tmp_path))
    t = controls_table(res)[0]
    rows = {r.labels[3]: (r.cells[0].plain(), r.cells[1].plain()) for r in t.rows if _psnr_noise_row(r)}
    assert len(rows) == 12
    text, mark = rows["type=Motion blur, severity=5 vs type=–, severity=0"]
    assert "*" in text and mark == UNMARKED
    holm_p = float(re.search(r"Holm p ([0-9.e-]+)", text).group(1))
    assert 0.05 < holm_p < 0.2
    assert all(m == UNMARKED for _, m in rows.values())
    got = _verdicts(res)
    # robustness "reproduced" whose interval includes zero: blind, like any verdict that shows no effect
    assert got["noise_gaussian"] == "blind: control depth_noise unmarked"
    # an interval that excludes zero is never blinded, whatever the robustness verdict
    assert got["noise_poisson"] == INCONCLUSIVE
    assert got["noise_salt_pepper"] == REPRODUCED


def test_a_row_that_survives_holm_marks_the_control(tmp_path: Path):
    _control_noise_runs(tmp_path, [-2.0, -2.02, -1.99])
    _noise_claim_runs(tmp_path, DROPS)
    res = Results(collect(tmp_path))
    t = controls_table(res)[0]
    marks = {r.labels[3]: r.cells[1].plain() for r in t.rows if _psnr_noise_row(r)}
    assert marks["type=Motion blur, severity=5 vs type=–, severity=0"] == MARKED
    assert _verdicts(res)["noise_gaussian"] == REPRODUCED


def test_captions_state_the_family_wise_reading(tmp_path: Path):
    _control_noise_runs(tmp_path, [-1.0, -1.2, -0.9])
    _noise_claim_runs(tmp_path, DROPS)
    res = Results(collect(tmp_path))
    controls = controls_table(res)[0].caption
    assert "This table has 12 intervals at 95 %" in controls and "0.05 · 12 = 0.6 of them exclude zero" in controls
    assert "Holm" in controls
    claims = claims_table(res)[0].caption
    # three robustness rows, two tests each (TOST, and a drop beyond the margin): one Holm family of six
    assert "6 tests in all, corrected together by Holm at 5 %" in claims


def test_paper_numbers_are_the_printed_ones():
    for c in PAPER_CLAIMS:
        if c.paper is None:
            continue
        assert c.paper == round(c.paper, c.paper_decimals), c.key
        for printed in re.findall(r"\d+\.\d+", c.paper_note):  # "24.81 vs 21.31 dB": as the paper prints them
            assert len(printed.split(".")[1]) == c.paper_decimals, c.key
    papers = {c.key: c.paper for c in PAPER_CLAIMS}
    assert papers["depth_mm_raw_psnr"] == 2.62 and papers["depth_ss_raw_psnr"] == 3.5
    assert papers["latent_32_16"] == -1.51 and papers["ordering_pose_filename"] == 2.36


def test_verdicts_compare_at_the_papers_precision():
    # an interval reaching +2.6199 reaches the paper's +2.62 at its two decimals
    assert verdict(+1, 0.5, 2.6199, paper=2.62, decimals=2) == REPRODUCED
    assert verdict(+1, 0.5, 2.6149, paper=2.62, decimals=2) == SMALLER
    assert verdict_text(SMALLER, +1, 0.5, 2.6149, 2.62, 2) == "smaller than claimed: at most +2.61, paper +2.62"
    assert verdict(-1, -1.504, -0.2, paper=-1.5, decimals=2) == REPRODUCED


def test_one_failed_seed_keeps_the_claim_paired(tmp_path: Path):
    # PSNR: minmax = raw_l1 + 3 on every seed; seed 2's raw_l1 run failed
    for s in range(4):
        for form, psnr in (("raw_l1", 21.0), ("minmax", 24.0)):
            failed = form == "raw_l1" and s == 2
            write_run(tmp_path, f"df/{form}_{s}", method="gaussiands", scene="bench", seed=s,
                      study="depth_formulation", grid={"gaussiands.depth_formulation": form},
                      status="failed" if failed else "done",
                      metrics={"psnr": None if failed else psnr + 2.0 * s + 0.01 * s * s})
    t = claims_table(Results(collect(tmp_path)))[0]
    row = next(r for r in t.rows if r.labels[0] == "min-max beats raw L1 depth (PSNR)")
    assert row.cells[1].plain().endswith("* (n=3, paired; dropped seed 2)")
    # +3.00 exactly on every seed: wholly beyond the paper's +2.62
    assert row.cells[3].plain() == "larger than claimed: at least +3.00, paper +2.62"
    assert row.cells[0].plain().startswith("+2.62 ")
