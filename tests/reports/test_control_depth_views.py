"""The depth control varies train.views beside lambda_depth. Each row is compared with lambda_depth 0
at its own view count (more views raise PSNR whatever lambda_depth does, so a row paired with another
count's reference would be marked for the wrong reason), and the guard of the depth claims is the
3-view rows alone: the 6- and 9-view rows are their own Holm family, so they cannot dilute it."""
from __future__ import annotations

from pathlib import Path

import pytest
from report_runs import write_run

from gsbench.collect import collect
from gsbench.reports.controls import CONTROLS, MARKED, UNMARKED, control_rows, control_status
from gsbench.reports.data import Results

SEED_NOISE = [0.0, 0.4, -0.3]   # shared by the two rows of a (seed, views): pairing removes it
# views -> (PSNR at lambda_depth 0, lambda_depth 1 minus 0 on seeds 0, 1, 2)
PSNR = {3: (20.0, (2.0, 2.01, 2.02)), 6: (24.0, (0.5, 0.52, 0.54)), 9: (26.0, (0.3, -0.3, 0.3))}


def _runs(root: Path) -> Results:
    for s in (0, 1, 2):
        for views, (base, effect) in PSNR.items():
            for lam in (0.0, 1.0):
                psnr = base + SEED_NOISE[s] + (effect[s] if lam else 0.0)
                covered = 0.09 - (0.05 + 0.001 * s if lam and views == 3 else 0.0)
                write_run(root, f"cd/{views}_{lam}_{s}", method="gaussiands", scene="bench", seed=s,
                          study="control_depth", grid={"train.views": views, "gaussiands.lambdas.depth": lam},
                          metrics={"psnr": psnr, "depth_absrel_covered": covered, "depth_coverage": 0.98})
    return Results(collect(root))


def _control(key: str):
    return next(c for c in CONTROLS if c.key == key)


def test_depth_rows_are_paired_at_their_own_view_count(tmp_path):
    res = _runs(tmp_path)
    guard = {r.label: r for r in control_rows(res, _control("depth_psnr"))}
    assert set(guard) == {"views=3, depth=1"}
    row = guard["views=3, depth=1"]
    assert row.diff.delta == pytest.approx(2.01)
    assert row.mark == MARKED and row.holm_p == pytest.approx(row.diff.p)   # a family of one row
    assert control_status(res, _control("depth_psnr")) == MARKED
    more = {r.label: r for r in control_rows(res, _control("depth_psnr_more_views"))}
    assert set(more) == {"views=6, depth=1", "views=9, depth=1"}
    # each against lambda_depth 0 at its own count (2 and 6 dB below), not another count's
    assert more["views=6, depth=1"].diff.delta == pytest.approx(0.52)
    assert more["views=9, depth=1"].diff.delta == pytest.approx(0.1)
    assert more["views=9, depth=1"].mark == UNMARKED
    error = _control("depth_error")
    assert error.metric == "depth_absrel_covered" and error.guards == ()
    rows = {r.label: r for r in control_rows(res, error)}
    assert rows["views=3, depth=1"].diff.delta == pytest.approx(-5.1)   # -5.0, -5.1, -5.2 points
    rows = {r.label: r for r in control_rows(res, _control("depth_error_more_views"))}
    assert rows["views=9, depth=1"].diff.delta == pytest.approx(0.0)


def test_a_control_without_runs_in_its_setting_is_not_run(tmp_path):
    for s in (0, 1):
        for lam in (0.0, 1.0):
            write_run(tmp_path, f"cd/3_{lam}_{s}", method="gaussiands", scene="bench", seed=s, study="control_depth",
                      grid={"train.views": 3, "gaussiands.lambdas.depth": lam}, metrics={"psnr": 20.0 + lam + s})
    res = Results(collect(tmp_path))
    rows = control_rows(res, _control("depth_psnr_more_views"))
    assert [(r.diff, r.note) for r in rows] == [(None, "no run in the control's setting")]
    assert control_status(res, _control("depth_psnr_more_views")) == "not run"
