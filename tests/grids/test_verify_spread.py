"""`gsbench verify` on another CPU: each re-run metric judged against the prediction interval of its
setting's published seeds (gsbench.grids.seed_spread), on a faked CPU name with a planted outlier."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import statsmodels.api as sm

from gsbench.grids import verify as verify_mod
from gsbench.grids.seed_spread import (
    NO_SPREAD,
    OUTSIDE,
    WITHIN,
    flip_prone,
    judge,
    prediction_interval,
    setting_key,
)
from gsbench.grids.store import Published
from gsbench.numerics import NUMERICS_VERSION

PUBLISHED_ON = {"cpu_model": "Intel(R) Xeon(R) Processor @ 2.50GHz", "cpu_flags": "84abf1c1f042a51b"}
OTHER_CPU = {"cpu_model": "AMD EPYC 9999 (faked)", "cpu_flags": "0000000000000000", "physical_cores": 2}


@pytest.mark.parametrize("values", [[1.0, 2.0, 3.0, 4.0], [25.1, 25.4, 24.9], [0.47, 0.52, 0.31, 0.44, 0.6, 0.5]])
def test_prediction_interval_is_statsmodels_ols_prediction_interval(values):
    """The interval of one new draw equals statsmodels' OLS observation interval of an intercept-only model."""
    y = np.asarray(values)
    frame = sm.OLS(y, np.ones((len(y), 1))).fit().get_prediction(np.ones((1, 1))).summary_frame(alpha=0.01)
    lo, hi = prediction_interval(values, alpha=0.01)
    assert lo == pytest.approx(float(frame["obs_ci_lower"].iloc[0]), rel=1e-12)
    assert hi == pytest.approx(float(frame["obs_ci_upper"].iloc[0]), rel=1e-12)


def test_no_interval_from_one_seed_and_a_point_from_identical_seeds():
    assert prediction_interval([3.0]) is None and prediction_interval([]) is None
    lo, hi = prediction_interval([0.25, 0.25, 0.25])
    assert lo < 0.25 < hi and hi - lo < 1e-6
    assert judge("x", 0.25, 0.25 * (1 + 1e-9), [_rec(0, {"x": 0.25}), _rec(1, {"x": 0.25})]).verdict == WITHIN
    assert judge("x", 0.25, 0.26, [_rec(0, {"x": 0.25}), _rec(1, {"x": 0.25})]).verdict == OUTSIDE
    assert judge("x", 0.25, 0.9, [_rec(0, {"x": 0.25})]).verdict == NO_SPREAD


def test_thresholded_and_encode_metrics_are_named_flip_prone():
    assert flip_prone("loc_acc_lerf") and flip_prone("miou_3dovs_encode_heldout") and flip_prone("loc_acc_lerf_heldout")
    assert not flip_prone("psnr") and not flip_prone("miou_3dovs_decode")


def _rec(seed: int, metrics: dict, axes: dict | None = None, grid: str = "control_sem-cpu") -> dict:
    return {"grid": grid, "run_id": f"{seed:016x}", "numerics_version": NUMERICS_VERSION,
            "cell": {"method": "gaussiands", "seed": seed, "axes": axes or {"gaussiands.lambdas.sem": 5.0},
                     "scene": {"preset": "tabletop-medium", "seed": 0}},
            "results": {"metrics": metrics}, "provenance": dict(PUBLISHED_ON)}


def _store() -> list[Published]:
    psnr = [25.2, 25.6, 24.9, 25.3]
    miou = [0.47, 0.55, 0.41, 0.50]
    cells = [Published(Path(f"s{i}.json"), _rec(i, {"psnr": p, "miou_3dovs": m, "loc_acc_lerf": 0.5, "fps": 100.0}))
             for i, (p, m) in enumerate(zip(psnr, miou))]
    # another setting of the same grid: its seeds must not widen the interval
    other = {"gaussiands.lambdas.sem": 0.0}
    cells += [Published(Path(f"o{i}.json"), _rec(i, {"psnr": 10.0 * i, "miou_3dovs": 0.0}, other)) for i in range(4)]
    return cells


def test_settings_differ_by_axes_not_by_seed():
    cells = _store()
    assert setting_key(cells[0].record) == setting_key(cells[3].record) != setting_key(cells[4].record)
    assert len(verify_mod.same_setting(cells[0], cells)) == 4


def test_verify_on_another_cpu_judges_by_the_seed_spread_and_fails_on_a_planted_outlier(monkeypatch, tmp_path):
    cells = _store()
    monkeypatch.setattr(verify_mod, "cpu_facts", lambda: dict(OTHER_CPU))
    rerun = {"psnr": 25.41, "miou_3dovs": 0.05, "loc_acc_lerf": 0.5, "fps": 1.0}     # mIoU planted far outside
    monkeypatch.setattr(verify_mod, "_rerun", lambda cell, work: {"metrics": dict(rerun)})
    check = verify_mod.verify_cell(cells[0], tmp_path, cells)
    assert not check.exact
    verdicts = {r.metric: r.verdict for r in check.rows}
    assert verdicts == {"psnr": WITHIN, "miou_3dovs": OUTSIDE, "loc_acc_lerf": WITHIN}    # fps is a timing
    assert not check.ok
    text = verify_mod.format_check(check)
    assert "judged by the seed spread" in text and "AMD EPYC 9999 (faked)" in text
    line = {ln.split()[0]: ln for ln in text.splitlines()[2:-1]}
    assert line["psnr"].endswith("within the seed spread") and "(4)" in line["psnr"]
    assert line["miou_3dovs"].endswith("outside")
    assert line["loc_acc_lerf"].endswith("(one ulp can flip it)")
    assert text.splitlines()[-1].endswith("1 outside the seed spread")
    rerun["miou_3dovs"] = 0.46
    assert verify_mod.verify_cell(cells[0], tmp_path, cells).ok


def test_verify_on_the_publishing_cpu_stays_exact(monkeypatch, tmp_path):
    cells = _store()
    monkeypatch.setattr(verify_mod, "cpu_facts", lambda: {**PUBLISHED_ON, "physical_cores": 2})
    metrics = dict(cells[0].metrics)
    metrics["psnr"] = math.nextafter(metrics["psnr"], 0.0)     # one ulp: inside any seed spread, still a mismatch
    monkeypatch.setattr(verify_mod, "_rerun", lambda cell, work: {"metrics": metrics})
    check = verify_mod.verify_cell(cells[0], tmp_path, cells)
    assert check.exact and not check.ok
    assert [r.metric for r in check.rows if not r.ok] == ["psnr"]


def test_a_rerun_uses_the_thread_count_the_cell_was_published_with(monkeypatch):
    # some reductions outside the training step split their work by the thread count: a cell published at
    # one thread re-runs at one thread, and the budget is put back afterwards
    import os

    import torch

    from gsbench.grids.verify import published_threads, thread_budget
    assert published_threads({"provenance": {"torch_threads": 1}}) == 1
    assert published_threads({"provenance": {"torch_threads": True}}) is None
    assert published_threads({"provenance": {"torch_threads": 0}}) is None
    assert published_threads({}) is None
    monkeypatch.delenv("GSBENCH_THREADS", raising=False)
    before = torch.get_num_threads()
    with thread_budget(1):
        assert os.environ["GSBENCH_THREADS"] == "1" and os.environ["MKL_NUM_THREADS"] == "1"
        assert torch.get_num_threads() == 1
    assert "GSBENCH_THREADS" not in os.environ and torch.get_num_threads() == before
    with thread_budget(None):
        assert "GSBENCH_THREADS" not in os.environ


def test_a_rerun_on_other_sparse_points_is_refused_with_both_digests(tiny_scene, tmp_path):
    # the points are a capture's initialisation and sit outside the scene fingerprint: the cell records them
    from gsbench.datasets import load_scene
    from gsbench.datasets.base import point_set_digest
    points = load_scene(tiny_scene).points
    assert points is not None and len(points) > 10
    cell = Published(tmp_path / "c.json", {})
    rec = {"config": {"scene": {"points": point_set_digest(points)}}}
    verify_mod._check_points(tiny_scene, rec, cell)        # the same points: no complaint
    verify_mod._check_points(tiny_scene, {"config": {"scene": {}}}, cell)   # an older cell records none
    moved = point_set_digest(points[1:])
    with pytest.raises(RuntimeError, match=f"sparse points {point_set_digest(points)}.*from points {moved}"):
        verify_mod._check_points(tiny_scene, {"config": {"scene": {"points": moved}}}, cell)
