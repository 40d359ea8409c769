"""The verdict words of issue 49: "larger than claimed", Holm across the claims table (statsmodels'
multipletests as the reference), the qualifications in the verdict column, TOST for robustness
(statsmodels' ttost_paired; its power by a scipy simulation), the within-seed analysis of the lambda
claims (statsmodels OLS with seed dummies), the two-look error rate, provenance and scope."""
from __future__ import annotations

import gc
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import statsmodels.formula.api as smf
from control_runs import write_marked_controls
from report_runs import write_run
from scipy import stats as sps
from statsmodels.stats.multitest import multipletests
from statsmodels.stats.weightstats import ttost_paired

from gsbench.collect import collect
from gsbench.grids.store import Published
from gsbench.reports.claims_page import machines, scene_kinds, scope_line, upgrades, verdict_summary
from gsbench.reports.claims_table import (
    INCONCLUSIVE,
    LARGER,
    NOT_REPRODUCED,
    OPPOSITE,
    REPRODUCED,
    SMALLER,
    claims_table,
    qualified,
    verdict,
    verdict_text,
)
from gsbench.reports.claims_tests import (
    mde_within_r,
    seeds_for_tost,
    seeds_for_within_r,
    tost,
    tost_power,
    two_look_error,
    within_seed,
)
from gsbench.reports.data import Results

DOCS = Path(__file__).resolve().parents[2] / "docs" / "grids.md"


@pytest.fixture
def no_gc(monkeypatch):
    """statsmodels' Holm runs gc.collect() on every call; it changes no result."""
    monkeypatch.setattr(gc, "collect", lambda *args: 0)


# ----------------------------------------------------------------------------- larger than claimed
def test_reproduced_only_when_the_paper_lies_inside_the_interval():
    assert verdict(+1, 0.5, 2.5, paper=2.0) == REPRODUCED
    assert verdict(+1, 2.1, 3.0, paper=2.0) == LARGER
    assert verdict(+1, 0.5, 1.9, paper=2.0) == SMALLER
    assert verdict(+1, -0.5, 1.9, paper=2.0) == NOT_REPRODUCED
    # the d 16 -> 32 row: -11.00 [-19.35, -2.65] against the paper's -1.51
    assert verdict(-1, -19.35, -2.65, paper=-1.51, decimals=2) == LARGER
    assert verdict_text(LARGER, -1, -19.35, -2.65, -1.51, 2) == "larger than claimed: at most -2.65, paper -1.51"
    # at the paper's decimals: a near end of +2.004 is +2.00, which the paper's +2.00 still reaches
    assert verdict(+1, 2.004, 3.0, paper=2.0, decimals=2) == REPRODUCED


def test_qualifications_go_before_the_detail():
    assert qualified("opposite", ["fails Holm"]) == "opposite (fails Holm)"
    assert qualified("not reproduced: at most +0.17, paper +3.50", ["after a second look"]) == \
        "not reproduced (after a second look): at most +0.17, paper +3.50"
    assert qualified("reproduced", []) == "reproduced"


# ----------------------------------------------------------------------------- Holm across the claims
def _formulation_runs(root: Path, shift: dict[str, list[float]]) -> None:
    """depth_formulation: raw_l1 at a seed-dependent PSNR, the other rows shifted per seed (PSNR in dB,
    mBIoU in %)."""
    write_marked_controls(root)  # marked in the same regime: the verdict words are read, not "blind"
    base = [21.0, 22.5, 20.2, 23.1]
    for s in range(4):
        write_run(root, f"df/raw_{s}", method="gaussiands", scene="bench", seed=s, study="depth_formulation",
                  grid={"gaussiands.depth_formulation": "raw_l1"}, metrics={"psnr": base[s], "mbiou_3dovs": 0.5})
        for form, d in shift.items():
            write_run(root, f"df/{form}_{s}", method="gaussiands", scene="bench", seed=s, study="depth_formulation",
                      grid={"gaussiands.depth_formulation": form},
                      metrics={"psnr": base[s] + d[s], "mbiou_3dovs": 0.5 + MBIOU[form][s] / 100.0})


SHIFTS = {"scale_shift": [3.4, 3.7, 3.2, 3.6],   # ss vs raw: +3.48 (reproduced, paper +3.50)
          "minmax": [0.5, 0.9, 0.6, 1.2]}       # mm vs raw: +0.80, p 0.015 alone (paper +2.62)
MBIOU = {"scale_shift": [30.0, -30.0, 25.0, -20.0], "minmax": [0.0, 10.0, -10.0, 5.0]}   # both inconclusive


def _rows(res: Results, **kw) -> dict[str, list[str]]:
    t = claims_table(res, **kw)[0]
    return {r.labels[0]: [c.plain() for c in r.cells] for r in t.rows if r.cells[1].plain() != "study not run"
            and not r.cells[1].plain().startswith("n/a")}


def test_holm_p_follows_statsmodels(tmp_path: Path, no_gc):
    _formulation_runs(tmp_path, SHIFTS)
    rows = _rows(Results(collect(tmp_path)))
    ss, mm = np.array(SHIFTS["scale_shift"]), np.array(SHIFTS["minmax"])
    bs, bm = np.array(MBIOU["scale_shift"]), np.array(MBIOU["minmax"])
    # the family, by scipy: each signed row's test of no effect and of the paper's value
    fam = {("ssb", "zero"): sps.ttest_1samp(bs, 0.0).pvalue, ("ssb", "paper"): sps.ttest_1samp(bs, 32.30).pvalue,
           ("ssmmb", "zero"): sps.ttest_1samp(bs - bm, 0.0).pvalue,
           ("ssmmb", "paper"): sps.ttest_1samp(bs - bm, 2.78).pvalue,
           ("ss_raw", "zero"): sps.ttest_1samp(ss, 0.0).pvalue, ("ss_raw", "paper"): sps.ttest_1samp(ss, 3.5).pvalue,
           ("mm_raw", "zero"): sps.ttest_1samp(mm, 0.0).pvalue, ("mm_raw", "paper"): sps.ttest_1samp(mm, 2.62).pvalue,
           ("ss_mm", "zero"): sps.ttest_1samp(ss - mm, 0.0).pvalue,
           ("ss_mm", "paper"): sps.ttest_1samp(ss - mm, 0.88).pvalue}
    _rej, adj, _, _ = multipletests(list(fam.values()), alpha=0.05, method="holm")
    holm = dict(zip(fam, adj))
    ss_raw = rows["scale-shift beats raw L1 depth (PSNR)"]
    assert ss_raw[3] == REPRODUCED   # rests on "no effect" alone
    assert ss_raw[5] == f"{fam[('ss_raw', 'zero')]:.2g} ({holm[('ss_raw', 'zero')]:.2g})"
    ss_mm = rows["scale-shift beats min-max depth (PSNR)"]
    assert ss_mm[3].startswith(LARGER)   # +2.8 against +0.88: rests on both, the larger p shown
    p = max(fam[("ss_mm", "zero")], fam[("ss_mm", "paper")])
    q = max(holm[("ss_mm", "zero")], holm[("ss_mm", "paper")])
    assert ss_mm[5] == f"{p:.2g} ({q:.2g})"
    assert ("fails Holm" in ss_mm[3]) == (q > 0.05)


def test_a_verdict_that_fails_holm_or_had_a_second_look_says_so(tmp_path: Path, no_gc):
    # mm vs raw: +0.5, +0.9, +0.6, +1.2: excludes zero alone (p 0.015) but not after Holm across the table
    _formulation_runs(tmp_path, SHIFTS)
    res = Results(collect(tmp_path))
    mm = np.array(SHIFTS["minmax"])
    assert sps.ttest_1samp(mm, 0.0).pvalue < 0.05
    rows = _rows(res)
    assert rows["min-max beats raw L1 depth (PSNR)"][3].startswith(SMALLER + " (fails Holm): at most +")
    later = _rows(res, later=frozenset(res.run_ids(study="depth_formulation")))
    assert later["scale-shift beats raw L1 depth (PSNR)"][3] == REPRODUCED + " (after a second look)"
    assert later["min-max beats raw L1 depth (PSNR)"][3].startswith(SMALLER + " (fails Holm; after a second look):")
    # an inconclusive verdict rejects nothing: never qualified
    assert later["scale-shift beats raw L1 depth (mBIoU)"][3] == INCONCLUSIVE


def test_verdict_counts_keep_the_qualifications(tmp_path: Path, no_gc):
    _formulation_runs(tmp_path, SHIFTS)
    res = Results(collect(tmp_path))
    t = claims_table(res, later=frozenset(res.run_ids(study="depth_formulation")))[0]
    summary = verdict_summary(t)
    assert "reproduced 1 (after a second look 1)" in summary
    assert "smaller than claimed 1 (fails Holm 1; after a second look 1)" in summary


# ----------------------------------------------------------------------------- TOST
def test_tost_follows_statsmodels_ttost_paired():
    a = np.array([24.1, 23.7, 24.9, 24.4, 23.8])
    b = np.array([24.0, 24.0, 24.6, 24.3, 24.1])
    d = a - b
    se = d.std(ddof=1) / math.sqrt(d.size)
    got = tost(float(d.mean()), se, d.size - 1, 0.5)
    p, (_t1, p1, _df1), (_t2, p2, _df2) = ttost_paired(a, b, -0.5, 0.5)
    assert got.p == pytest.approx(p, rel=1e-9)
    assert got.p_lower == pytest.approx(p1, rel=1e-9) and got.p_upper == pytest.approx(p2, rel=1e-9)
    # TOST at 5 % a side rejects exactly when the 90 % t interval lies inside the margin
    lo, hi = sps.t.interval(0.90, d.size - 1, loc=d.mean(), scale=se)
    assert (got.lo, got.hi) == pytest.approx((lo, hi), rel=1e-9)
    assert (got.p < 0.05) == (-0.5 < lo and hi < 0.5)


def _tost_power_by_simulation(sd: float, n: int, margin: float, draws: int = 40_000) -> float:
    rng = np.random.default_rng(7)
    d = rng.normal(0.0, sd, (draws, n))
    m, se = d.mean(axis=1), d.std(axis=1, ddof=1) / math.sqrt(n)
    c = sps.t.ppf(0.95, n - 1)
    return float(np.mean((m - c * se > -margin) & (m + c * se < margin)))


@pytest.mark.parametrize("sd,n", [(0.4, 4), (0.4, 6), (0.6, 10), (0.25, 3)])
def test_tost_power_matches_a_simulation(sd: float, n: int):
    sim = _tost_power_by_simulation(sd, n, 0.5)
    se = math.sqrt(sim * (1 - sim) / 40_000)
    assert abs(tost_power(sd, n, 0.5) - sim) < 4 * se + 1e-3


def test_tost_seed_rule_is_the_first_n_with_80_percent_power():
    n = seeds_for_tost(0.4, 0.5)
    assert n == 8   # sd 0.4 dB, margin 0.5 dB: the simulation below has 8 seeds over 0.8 and 7 under it
    assert _tost_power_by_simulation(0.4, 8, 0.5) > 0.8 > _tost_power_by_simulation(0.4, 7, 0.5)


# ----------------------------------------------------------------------------- within-seed analysis
def _lambda_frame() -> pd.DataFrame:
    """Four seeds far apart (seed offsets of 10 to 40 mIoU points) and a within-seed slope of -0.05."""
    rng = np.random.default_rng(3)
    rows = []
    for s, offset in enumerate([10.0, 40.0, 25.0, 33.0]):
        for lam in (0.0, 0.1, 0.5, 1.0, 2.0, 5.0, 10.0):
            rows.append({"seed": s, "x": lam, "y": offset - 0.05 * lam + rng.normal(0.0, 0.1)})
    return pd.DataFrame(rows)


def test_within_seed_slope_follows_statsmodels_ols():
    df = _lambda_frame()
    fit, why = within_seed(list(df.seed), list(df.x), list(df.y))
    assert why is None and fit is not None
    ols = smf.ols("y ~ x + C(seed)", data=df).fit()
    assert fit.slope == pytest.approx(ols.params["x"], rel=1e-9)
    assert (fit.slope_lo, fit.slope_hi) == pytest.approx(tuple(ols.conf_int().loc["x"]), rel=1e-9)
    assert fit.p == pytest.approx(ols.pvalues["x"], rel=1e-6)
    assert fit.df == ols.df_resid == len(df) - 4 - 1
    # the within-seed r is the partial r: t / sqrt(t^2 + df); its Fisher-z interval on n - seeds - 2
    t = ols.tvalues["x"]
    assert fit.r == pytest.approx(t / math.sqrt(t * t + ols.df_resid), rel=1e-9)
    half = sps.norm.ppf(0.975) / math.sqrt(len(df) - 4 - 2)
    assert fit.r_lo == pytest.approx(math.tanh(math.atanh(fit.r) - half), rel=1e-9)
    # pooled over seeds the same data say nothing: the seed offsets swamp the slope
    assert abs(sps.pearsonr(df.x, df.y)[0]) < 0.1 < -fit.r


def test_within_seed_seed_rule():
    # 17 lambda settings a seed, target |r| 0.345 (half the paper's 0.69)
    s = seeds_for_within_r(0.345, 17)
    zpow = sps.norm.ppf(0.975) + sps.norm.ppf(0.8)
    assert math.tanh(zpow / math.sqrt(s * 17 - s - 2)) <= 0.345 < math.tanh(zpow / math.sqrt((s - 1) * 17 - s + 1 - 2))
    assert mde_within_r(68, 4) == pytest.approx(math.tanh(zpow / math.sqrt(62)), rel=1e-12)


def test_lambda_claims_read_within_seeds(tmp_path: Path):
    df = _lambda_frame()
    for i, row in df.iterrows():
        write_run(tmp_path, f"l/{i}", method="gaussiands", scene="bench", seed=int(row.seed), study="lambda_grid",
                  grid={"gaussiands.lambdas.depth": 0.1, "gaussiands.lambdas.sem": float(row.x)},
                  metrics={"miou_3dovs": float(row.y) / 100.0})
    rows = _rows(Results(collect(tmp_path)))
    text, verdict_cell = rows["lambda_sem correlates positively with mIoU"][1], \
        rows["lambda_sem correlates positively with mIoU"][3]
    ols = smf.ols("y ~ x + C(seed)", data=df).fit()
    assert f"slope {ols.params['x']:+.3f} [" in text and "(n=28, 4 seeds)" in text
    assert verdict_cell.startswith(OPPOSITE)


# ----------------------------------------------------------------------------- two looks
def test_two_look_error_is_reproducible_and_matches_an_independent_simulation():
    got = two_look_error(3, 6)
    assert got == two_look_error(3, 6)           # fixed RNG seed
    rng = np.random.default_rng(123)
    x = rng.standard_normal((20_000, 6))
    first = sps.ttest_1samp(x[:, :3], 0.0, axis=1).pvalue < 0.05
    second = sps.ttest_1samp(x, 0.0, axis=1).pvalue < 0.05
    ref = float(np.mean(first | second))
    assert abs(got - ref) < 4 * math.sqrt(ref * (1 - ref) / 20_000) + 1e-3
    assert got > 0.08   # well above one look's 5 %, and above the "at most about 8 %" the docs once said


def test_docs_print_the_simulated_two_look_rates():
    text = DOCS.read_text(encoding="utf-8")
    for n1, n2 in ((3, 4), (3, 6), (3, 10), (6, 12)):
        assert f"{100 * two_look_error(n1, n2):.1f} %" in text, (n1, n2)
    assert "at most about 8 %" not in text


# ----------------------------------------------------------------------------- provenance and scope
def _cell(grid: str, prov: dict, scene: dict | None = None, study: str = "depth_formulation") -> Published:
    rec = {"grid": grid, "run_id": "r", "numerics_version": 1, "study": study, "provenance": prov,
           "cell": {"scene": scene or {"preset": "tabletop-medium", "seed": 0}},
           "config": {"scene": {"name": "tabletop-medium-0"}},
           "results": {"scene": "tabletop-medium-0", "split": {"trained_ids": list(range(21))},
                       "providers": {"depth": "gt-sim-disparity-v3:d1:w518", "masks": "gt-instances"}}}
    return Published(Path("x.json"), rec)


def test_provenance_says_unknown_without_the_dirty_flag_and_names_uncommitted_upgrades():
    lines = [line for line, _n in machines([_cell("g", {"gsbench_commit": "a" * 40}),
                                           _cell("g", {"gsbench_commit": "b" * 40, "gsbench_commit_dirty": False}),
                                           _cell("g", {"gsbench_commit": "c" * 40, "gsbench_commit_dirty": True})])]
    assert any(ln.startswith("commit aaaaaaaaaaaa, tree state unknown") for ln in lines)
    assert any(ln.startswith("commit bbbbbbbbbbbb, clean tree") for ln in lines)
    assert any(ln.startswith("commit cccccccccccc with uncommitted changes") for ln in lines)
    up = upgrades([_cell("ctl", {"upgraded": {"by_commit": "d" * 40 + " (uncommitted changes)"}}),
                   _cell("ctl", {"upgraded": {"by_commit": "d" * 40 + " (uncommitted changes)"}}),
                   _cell("sem", {"upgraded": {"by_commit": "e" * 40}}), _cell("g", {})])
    assert up == ["- 2 cells of ctl: rewritten by `gsbench publish --upgrade` at commit dddddddddddd from a tree "
                  "with uncommitted changes",
                  "- 1 cells of sem: rewritten by `gsbench publish --upgrade` at commit eeeeeeeeeeee"]


def test_scope_labels_scenes_synthetic_or_real():
    synthetic = _cell("g", {})
    assert scene_kinds([synthetic]) == {"tabletop-medium-0": "synthetic"}
    line = scope_line([synthetic], 20)
    assert line.startswith("Scope: the 20 claim rows are measured on tabletop-medium-0 (synthetic, 21 training views)")
    assert "no claim row is measured on a real capture" in line
    real = _cell("g", {}, scene={"path": "scenes/dtu_scan37"})
    assert scene_kinds([real]) == {"tabletop-medium-0": "real"}
    assert "no claim row is measured on a real capture" not in scope_line([real], 20)
