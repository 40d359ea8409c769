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
        assert all(s.resolution == [48, 36] for s in q.scenes)
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
        cmd = [sys.executable, "-c", _SMALLER_QUICK, "claims", "--quick", "--executor", "serial", "--no-progress",
               "--out", str(out)]
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
        assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
        table = (out / "report" / "tables" / "paper_claims.md").read_text()
        assert "study not run" not in table and "| not run |" not in table
        for c in PAPER_CLAIMS:
            assert c.text in table
        controls = (out / "report" / "tables" / "claims_controls.md").read_text()
        assert "study not run" not in controls
        assert "Paper claims" in p.stdout and "Positive controls" in p.stdout
    finally:
        shutil.rmtree(out, ignore_errors=True)


def test_claims_list_and_unknown_grid(tmp_path, capsys):
    from gsbench.cli import main
    assert main(["claims", "--out", str(tmp_path / "r"), "--list"]) == 0
    out = capsys.readouterr().out
    assert "control_depth-cpu" in out and "431 cells in 11 grids" in out
    assert main(["claims", "--out", str(tmp_path / "r"), "--grids", "tiny-test"]) == 1
    assert "not in the claims plan" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()   # nothing planned or written
