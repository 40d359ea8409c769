"""The depth-noise control reads the same runs twice: PSNR (the guard of the depth-noise claims) and the
rendered-depth error (does the noise reach the geometry at all?). The second guards nothing, so a marked
depth error cannot un-blind a PSNR claim."""
from __future__ import annotations

import pytest
from report_runs import write_run

from gsbench.collect import collect
from gsbench.reports.controls import CONTROLS, MARKED, UNMARKED, control_rows, control_status
from gsbench.reports.data import Results

# (type, severity) -> (PSNR minus clean, covered depth error minus clean) on seeds 0, 1, 2
EFFECT = {(None, 0): ((0.0,) * 3, (0.0,) * 3),
          ("gaussian", 5): ((0.1, -0.2, 0.05), (0.050, 0.052, 0.049))}


def _control(key: str):
    return next(c for c in CONTROLS if c.key == key)


def test_noise_that_moves_the_depth_error_but_not_psnr_marks_only_the_error_control(tmp_path):
    for (kind, sev), (dpsnr, derr) in EFFECT.items():
        for s in range(3):
            write_run(tmp_path, f"cdn/{kind}_{sev}_{s}", method="gaussiands", scene="bench", seed=s,
                      study="control_depth_noise",
                      grid={"priors.depth.noise.type": kind, "priors.depth.noise.severity": sev},
                      metrics={"psnr": 23.0 + 0.3 * s + dpsnr[s], "depth_absrel_covered": 0.04 + 0.002 * s + derr[s],
                               "depth_coverage": 0.98})
    res = Results(collect(tmp_path))
    error, psnr = _control("depth_noise_error"), _control("depth_noise")
    assert error.guards == () and psnr.guards
    rows = {r.label: r for r in control_rows(res, error)}
    assert list(rows) == ["type=Gaussian, severity=5"]
    assert rows["type=Gaussian, severity=5"].diff.delta == pytest.approx(5.03, abs=0.01)   # points of AbsRel
    assert control_status(res, error) == MARKED
    assert control_status(res, psnr) == UNMARKED
