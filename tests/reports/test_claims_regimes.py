"""Regime-matched guarding (issue 49): a regime is derived from a cell's stored config, a positive control
guards a claim only in the claim's regime (the exact version of the claim's depth prior allowed, and
named), a claim with no marked control in its regime reads "blind: no control in this regime" wherever its
interval includes zero (a robustness "reproduced" too), and the claim x regime matrix takes its columns from
the declared regimes. Hand-made cells: the regime is what each run's config says."""
from __future__ import annotations

import copy
from pathlib import Path

from control_runs import with_grid, write_marked_controls
from report_runs import write_run

from gsbench.collect import collect
from gsbench.grids import claims_plan
from gsbench.grids.claims_plan import REGIMES, DeclaredRegime, Regime
from gsbench.reports import claims_matrix, regimes
from gsbench.reports.claims_matrix import matrix_table
from gsbench.reports.claims_table import PAPER_CLAIMS, REPRODUCED, claim_rows, claims_table
from gsbench.reports.data import Results
from gsbench.reports.regimes import EXACT_DEPTH, guard_note, preset_of, regime_of

# the dense synthetic regime as a cell's resolved config writes it (cpu-medium's schedule)
DENSE = {"train": {"iterations": 800, "max_width": 256, "views": None},
         "priors": {"depth": {"provider": "gt", "distortion": 1.0, "noise": {"type": None, "severity": 0}},
                    "masks": {"provider": "simulated", "severity": 1.0}, "features": {"provider": "text-aligned"}}}
SCENE = "tabletop-medium-0"
CLEAN = {"priors.depth.noise.type": None, "priors.depth.noise.severity": 0}


def _config(views=None, distortion=1.0, masks="simulated") -> dict:
    c = copy.deepcopy(DENSE)
    c["train"]["views"] = views
    c["priors"]["depth"]["distortion"] = distortion
    c["priors"]["masks"]["provider"] = masks
    return c


def _poisson_claim(root: Path) -> None:
    """depth_noise in the dense regime: poisson at severity 5 against the clean prior moves PSNR by
    +0.02, -0.03, +0.01 dB: TOST 'reproduced', its interval includes zero."""
    clean, poisson = CLEAN, {"priors.depth.noise.type": "poisson", "priors.depth.noise.severity": 5}
    for s, move in zip((0, 1, 2), (0.02, -0.03, 0.01)):
        write_run(root, f"dn/clean_{s}", method="gaussiands", scene=SCENE, seed=s, study="depth_noise",
                  grid=clean, metrics={"psnr": 24.0 + 0.3 * s}, config_extra=with_grid(_config(), clean))
        write_run(root, f"dn/poisson_{s}", method="gaussiands", scene=SCENE, seed=s, study="depth_noise",
                  grid=poisson, metrics={"psnr": 24.0 + 0.3 * s + move}, config_extra=with_grid(_config(), poisson))


def _poisson_row(res: Results) -> tuple[str, str, str]:
    """(Regime, Guarded by, Verdict) of the poisson robustness row."""
    t = claims_table(res)[0]
    row = next(r for r in t.rows if r.labels[0] == "PSNR is robust to poisson noise on the depth prior")
    return row.labels[2], row.labels[3], row.cells[3].plain()


def test_a_regime_comes_from_the_stored_config():
    assert preset_of({"train": {"iterations": 800, "max_width": 256}}) == "cpu-medium"
    assert preset_of({"train": {"iterations": 3200, "max_width": 256}}) == "cpu-real"
    assert preset_of({"train": {"iterations": 500, "max_width": 96}}) == "cpu-small"
    assert preset_of({"train": {"iterations": 123, "max_width": 64}}) == "custom (123 steps, width 64)"
    got = regime_of(_config(), SCENE)
    assert got == Regime(SCENE, None, "cpu-medium", "gt", 1.0, "simulated", "text-aligned")
    assert got == REGIMES[0].regime and REGIMES[0].name == "dense synthetic"
    # the depth prior's noise is a study setting, not part of the regime
    noisy = _config()
    noisy["priors"]["depth"]["noise"] = {"type": "poisson", "severity": 5}
    assert regime_of(noisy, SCENE) == got
    assert regime_of(_config(views=3), SCENE).views == 3


def test_only_the_exact_depth_prior_may_differ():
    claim = regime_of(_config(), SCENE)
    assert guard_note(regime_of(_config(), SCENE), claim) == ""
    assert guard_note(regime_of(_config(distortion=0.0), SCENE), claim) == EXACT_DEPTH
    assert guard_note(regime_of(_config(distortion=0.5), SCENE), claim) is None     # another version, not exact
    assert guard_note(regime_of(_config(masks="gt"), SCENE), claim) is None
    assert guard_note(regime_of(_config(views=3), SCENE), claim) is None
    assert guard_note(regime_of(_config(), "room-many-0"), claim) is None
    # an exact claim prior has no other exact version: a control with the default prior does not guard it
    assert guard_note(claim, regime_of(_config(distortion=0.0), SCENE)) is None


def test_a_control_from_another_regime_does_not_guard_the_claim(tmp_path: Path):
    """The failure issue 49 describes: the depth-noise control marks at 3 training views with the exact prior
    and GT masks; the claim is decided at all views. That control must not vouch for it."""
    _poisson_claim(tmp_path)
    write_marked_controls(tmp_path, scene="tabletop-medium-0-v24", config=_config(views=3, distortion=0.0, masks="gt"),
                          studies=("control_depth_noise",))
    regime, guard, verdict = _poisson_row(Results(collect(tmp_path)))
    assert regime.startswith("dense synthetic: tabletop-medium-0")
    assert guard == "none here (depth_noise ran in another regime)"
    # a robustness "reproduced" whose interval includes zero is blinded like any other
    assert verdict == "blind: no control in this regime"


def test_a_control_differing_in_one_provider_does_not_guard(tmp_path: Path):
    _poisson_claim(tmp_path)
    write_marked_controls(tmp_path, scene=SCENE, config=_config(masks="gt"), studies=("control_depth_noise",))
    assert _poisson_row(Results(collect(tmp_path)))[2] == "blind: no control in this regime"


def test_a_control_in_the_claims_regime_guards_it(tmp_path: Path):
    _poisson_claim(tmp_path)
    write_marked_controls(tmp_path, scene=SCENE, config=_config(), studies=("control_depth_noise",))
    _regime, guard, verdict = _poisson_row(Results(collect(tmp_path)))
    assert guard == "depth_noise marked, row type=Gaussian, severity=5"
    assert verdict.startswith(REPRODUCED)


def test_a_control_with_the_exact_depth_prior_guards_and_says_so(tmp_path: Path):
    _poisson_claim(tmp_path)
    write_marked_controls(tmp_path, scene=SCENE, config=_config(distortion=0.0), studies=("control_depth_noise",))
    _regime, guard, verdict = _poisson_row(Results(collect(tmp_path)))
    assert guard == f"depth_noise marked, row type=Gaussian, severity=5 ({EXACT_DEPTH})"
    assert verdict.startswith(REPRODUCED)


def test_an_unmarked_control_in_the_regime_blinds_with_its_name(tmp_path: Path):
    _poisson_claim(tmp_path)
    # the compared row moves by -0.1, +0.1, -0.1 dB: no mark
    for s, move in zip((0, 1, 2), (-0.1, 0.1, -0.1)):
        for tag, grid, m in (("ref", CLEAN, 0.0),
                             ("row", {"priors.depth.noise.type": "gaussian", "priors.depth.noise.severity": 5}, move)):
            write_run(tmp_path, f"cdn/{tag}_{s}", method="gaussiands", scene=SCENE, seed=s, study="control_depth_noise",
                      grid=grid, metrics={"psnr": 22.0 + 0.2 * s + m}, config_extra=with_grid(_config(), grid))
    _regime, guard, verdict = _poisson_row(Results(collect(tmp_path)))
    assert guard == "depth_noise unmarked" and verdict == "blind: control depth_noise unmarked"


def test_a_claim_with_no_control_declared_is_blind_where_it_shows_nothing(tmp_path: Path):
    # pose vs filename order: +1, -1, +1 points (includes zero); no control is declared for the ordering claims
    for s in (0, 1, 2):
        for order, v in (("pose", 0.5 + 0.01 * (-1) ** s), ("filename", 0.5)):
            write_run(tmp_path, f"o/{order}_{s}", method="gaussiands", scene=SCENE, seed=s, study="ordering",
                      grid={"priors.ordering": order}, metrics={"ordering_adjacent_mask_iou_strict": v},
                      config_extra=_config())
    rows = {r.claim.key: r for r in claim_rows(Results(collect(tmp_path)))}
    assert rows["ordering_pose_filename"].guard.text == "none declared for this claim"
    assert rows["ordering_pose_filename"].measured.verdict == "blind: no control in this regime"


def test_the_matrix_columns_are_the_declared_regimes(tmp_path: Path, monkeypatch):
    _poisson_claim(tmp_path)
    res = Results(collect(tmp_path))
    t = matrix_table(claim_rows(res))
    assert [c.header() for c in t.columns] == [d.name for d in REGIMES]
    row = next(r for r in t.rows if r.labels[0] == "PSNR is robust to poisson noise on the depth prior")
    assert [c.plain() for c in row.cells] == ["blind: no control in this regime", "not run", "not run"]
    # every claim has a row, the untestable ones marked
    assert len(t.rows) == len(PAPER_CLAIMS)
    assert any(r.labels[0].endswith(claims_matrix.UNTESTABLE_MARK) for r in t.rows)
    # a regime declared later is one more entry: its column appears, 'not run' until its cells exist
    extra = DeclaredRegime("few-view real", "real", Regime("dtu_scan37", 6, "cpu-real", "sfm", None, "gt",
                                                           "text-aligned"), "a test declaration")
    for module in (claims_plan, regimes, claims_matrix):
        monkeypatch.setattr(module, "REGIMES", (*REGIMES, extra))
    t = matrix_table(claim_rows(Results(collect(tmp_path))))
    assert [c.header() for c in t.columns][-1] == "few-view real"
    assert all(r.cells[-1].plain() == "not run" for r in t.rows)


def test_a_claim_in_an_undeclared_regime_gets_its_own_column(tmp_path: Path):
    _poisson_claim(tmp_path / "a")
    t = matrix_table(claim_rows(Results(collect(tmp_path / "a"))))
    assert len(t.columns) == len(REGIMES)
    for s in (0, 1, 2):
        for kind, sev in ((None, 0), ("poisson", 5)):
            grid = {"priors.depth.noise.type": kind, "priors.depth.noise.severity": sev}
            write_run(tmp_path / "a", f"dn9/{kind}_{s}", method="gaussiands", scene=SCENE, seed=s, study="depth_noise",
                      grid=grid, metrics={"psnr": 23.0 + 0.1 * s}, config_extra=with_grid(_config(views=9), grid))
    t = matrix_table(claim_rows(Results(collect(tmp_path / "a"))))
    assert t.columns[-1].header().startswith("other: tabletop-medium-0, 9 views, cpu-medium")


def test_a_cell_whose_depth_provider_was_auto_is_in_the_regime_of_what_auto_chose():
    from gsbench.reports.regimes import regime_of
    base = {"priors": {"depth": {"provider": "auto", "distortion": 1.0}, "masks": {"provider": "gt"},
                       "features": {"provider": "text-aligned"}}, "train": {"views": 3}}
    settled = {**base, "resolved": {"priors.depth.provider": "gt"}}
    explicit = {**base, "priors": {**base["priors"], "depth": {"provider": "gt", "distortion": 1.0}}}
    assert regime_of(settled, "s") == regime_of(explicit, "s")
    assert regime_of(settled, "s").depth == "gt" and regime_of(settled, "s").depth_distortion == 1.0
    assert regime_of(base, "s").depth == "auto"   # never settled: its own regime, matching no declared one
