"""`gsbench claims --quick` end to end: every grid of the plan at tiny scale, then the claims and
controls tables (every claim has a row and no row says "study not run")."""
from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from gsbench.grids.claims_plan import CLAIM_GRIDS, CONTROL_GRIDS, plan_grids


def test_quick_plan_is_the_same_cells_smaller():
    full, quick = plan_grids(), plan_grids(quick=True)
    assert [g.name for g in full] == [g.name for g in quick] == list(CLAIM_GRIDS + CONTROL_GRIDS)
    for f, q in zip(full, quick):
        assert q.seeds == [0, 1] and q.blocks == f.blocks and q.extra_cells == f.extra_cells
        assert all(s.resolution == [48, 36] for s in q.scenes if s.preset)   # a capture folder is kept as it is
        assert q.base_set["train.iterations"] == 20
        # the same cells per seed
        assert len(q.cells()) * len(f.seeds) == len(f.cells()) * len(q.seeds)


# `gsbench claims --quick` in a fresh interpreter with the quick plan shrunk further (one seed, 16x12 px,
# 4 views, 1 iteration, 1 autoencoder epoch): what this test checks (every grid runs, every claim and control
# gets a row) does not depend on the cells' size, and test_quick_plan_is_the_same_cells_smaller pins the
# shipped quick sizes; this cuts the test from ~6 min to under a minute on 2 cores.
_SMALLER_QUICK = """
import sys
import gsbench.grids.claims_plan as c
c.QUICK_SEEDS[:] = [0]
c.QUICK_RESOLUTION[:] = [16, 12]
c.QUICK_VIEWS = 4
c.QUICK_SET.update({"train.iterations": 1, "train.max_width": 16, "semantic.autoencoder.epochs": 1})
from gsbench.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow
def test_claims_quick_end_to_end():
    from gsbench.reports.claims_table import PAPER_CLAIMS
    out = Path(tempfile.mkdtemp(prefix="gsbench-claims-quick-"))   # outside pytest's rotating basetemp
    try:
        # every grid whose scenes are generated (the real capture's grid needs its folder: see the next test)
        local = [g.name for g in plan_grids() if not any(s.path for s in g.scenes)]
        cmd = [sys.executable, "-c", _SMALLER_QUICK, "claims", "--quick", "--executor", "serial", "--no-progress",
               "--out", str(out), "--grids", *local]
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
        assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
        table = (out / "report" / "tables" / "paper_claims.md").read_text()
        assert "study not run" not in table and "| not run |" not in table
        for c in PAPER_CLAIMS:
            assert c.text in table
        controls = (out / "report" / "tables" / "claims_controls.md").read_text()
        # a control whose grids all need the capture's folder (control_depth_real, control_ds_real) is the only
        # one left "not run" here
        local_studies = {g.study for g in plan_grids() if g.name in local}
        unrun = [ln.split("|")[2].split()[0] for ln in controls.splitlines() if "study not run" in ln]
        assert unrun and not set(unrun) & local_studies, unrun
        assert "Paper claims" in p.stdout and "Positive controls" in p.stdout
    finally:
        shutil.rmtree(out, ignore_errors=True)


def test_claims_list_and_unknown_grid(tmp_path, capsys):
    from gsbench.cli import main
    assert main(["claims", "--out", str(tmp_path / "r"), "--list"]) == 0
    out = capsys.readouterr().out
    assert "control_depth-cpu" in out and "718 cells in 29 grids" in out
    assert main(["claims", "--out", str(tmp_path / "r"), "--grids", "tiny-test"]) == 1
    assert "not in the claims plan" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()   # nothing planned or written


def test_a_grid_whose_capture_is_not_here_is_named_and_skipped(tmp_path, monkeypatch, capsys):
    from gsbench.cli import main
    from gsbench.grids.grid_file import load_grid
    from gsbench.grids.planning import missing_scene_folders
    monkeypatch.delenv("GSBENCH_SCENES", raising=False)
    real = load_grid("headline-real-cpu")
    assert missing_scene_folders(real) == ["scene '$GSBENCH_SCENES/dtu_scan37': unset environment variable in the path"]
    monkeypatch.setenv("GSBENCH_SCENES", str(tmp_path / "captures"))
    assert missing_scene_folders(real) == [f"scene {tmp_path / 'captures' / 'dtu_scan37'}: folder not found"]
    assert missing_scene_folders(load_grid("headline-cpu")) == []   # generated scenes are never missing
    # the plan goes on without it, says why, and exits 1 (the plan is not complete)
    assert main(["claims", "--out", str(tmp_path / "r"), "--grids", "headline-real-cpu", "--no-progress",
                 "--no-store"]) == 1
    err = capsys.readouterr().err
    assert "grid headline-real-cpu skipped: scene" in err and "folder not found" in err
