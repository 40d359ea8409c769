"""The claims page's spread table: variance shares of seed and setting against statsmodels' two-way
ANOVA, and a study whose metric follows only the seed (or only the setting) read as such."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from report_runs import write_run
from statsmodels.formula.api import ols
from statsmodels.stats.anova import anova_lm

from gsbench.collect import collect
from gsbench.reports.claims_spread import spread_table, variance_shares
from gsbench.reports.data import Results


def test_shares_follow_statsmodels_two_way_anova():
    rng = np.random.default_rng(3)
    table = rng.normal(0, 1, (6, 4)) + rng.normal(0, 2, (1, 4)) + rng.normal(0, 0.5, (6, 1))
    df = pd.DataFrame([{"y": table[i, j], "setting": f"s{i}", "seed": f"k{j}"}
                       for i in range(6) for j in range(4)])
    aov = anova_lm(ols("y ~ C(setting) + C(seed)", data=df).fit())
    total = float(aov["sum_sq"].sum())
    sh = variance_shares(table)
    assert sh.setting == pytest.approx(aov.loc["C(setting)", "sum_sq"] / total, rel=1e-9)
    assert sh.seed == pytest.approx(aov.loc["C(seed)", "sum_sq"] / total, rel=1e-9)
    assert sh.rest == pytest.approx(aov.loc["Residual", "sum_sq"] / total, rel=1e-9)
    assert sh.sd_seeds == pytest.approx(np.mean([np.std(r, ddof=1) for r in table]))


def test_no_shares_without_a_two_by_two_table_or_variance():
    assert variance_shares(np.ones((3, 3))) is None
    assert variance_shares(np.arange(3.0).reshape(1, 3)) is None
    assert variance_shares(np.array([[1.0, np.nan], [2.0, 3.0]])) is None


def test_a_study_whose_miou_follows_the_seed_reads_so(tmp_path: Path):
    seed_miou = {0: 0.75, 1: 0.46, 2: 0.54}
    for s in range(3):
        for i, form in enumerate(("none", "raw_l1", "minmax", "scale_shift")):
            if form == "minmax" and s == 2:
                continue  # a failed cell: the setting is left out, and the table says so
            write_run(tmp_path, f"df/{form}_{s}", method="gaussiands", scene="bench", seed=s,
                      study="depth_formulation", grid={"gaussiands.depth_formulation": form},
                      metrics={"psnr": 20.0 + i, "mbiou_3dovs": seed_miou[s] + 0.001 * i})
    t = spread_table(Results(collect(tmp_path)))[0]
    rows = {r.labels[1]: [c.plain() for c in r.cells] for r in t.rows}
    assert rows["PSNR (dB)"][0] == "3 x 3 (1 left out)"
    assert rows["PSNR (dB)"][3:] == ["0 %", "100 %", "0 %"]     # PSNR: the setting alone
    assert rows["mBIoU (%)"][3:5] == ["100 %", "0 %"]           # mBIoU: the seed alone
    assert all(r.labels[0] == "depth_formulation" for r in t.rows)


def test_no_table_without_a_claim_study(tmp_path: Path):
    write_run(tmp_path, "solo", method="vanilla", scene="bench", metrics={"psnr": 20.0})
    assert spread_table(Results(collect(tmp_path))) == []
