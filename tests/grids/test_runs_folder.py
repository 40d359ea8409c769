"""The runs folder of `ablate` and `claims` (gsbench/grids/runs_folder.py): one writer at a time, the
loser exits 1 with one line naming the folder and the holder and leaves nothing behind; a folder of
someone else's files is refused, or with --force left alone."""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gsbench import grids
from gsbench.cli import main
from gsbench.grids.claims_plan import CLAIM_GRIDS
from gsbench.grids.runs_folder import foreign_entries
from gsbench.runlock import read_holder

HOLD = """
import sys, time
from gsbench.runlock import RunLock
RunLock(sys.argv[1], command="gsbench ablate (the winner)", what="runs folder").acquire()
print("held", flush=True)
time.sleep(120)
"""

# `gsbench ablate` whose cells write a results.json and then wait until a gate file (first argv) exists
WINNER = """
import sys, time
from pathlib import Path
from gsbench.grids import running
from gsbench.store import write_json_atomic
def cell(spec, run_dir, status):
    write_json_atomic(run_dir / "results.json", {"metrics": {}})
    while not Path(sys.argv[1]).exists():
        time.sleep(0.05)
running._train_and_evaluate = cell
from gsbench.cli import main
sys.exit(main(sys.argv[2:]))
"""


def _ablate(runs: Path, *extra: str) -> list[str]:
    return ["ablate", "--grid", "tiny-test", "--out", str(runs), "--executor", "serial", "--no-progress", *extra]


def _last_line(err: str) -> str:
    return [ln for ln in err.splitlines() if ln.strip()][-1]


def _litter(runs: Path) -> list[str]:
    return sorted(str(p.relative_to(runs)) for p in runs.rglob("*") if p.name.endswith(".takeover"))


def test_the_ablate_loser_fails_with_one_line_and_leaves_nothing(tmp_path, capsys):
    runs = tmp_path / "runs"
    p = subprocess.Popen([sys.executable, "-c", HOLD, str(runs)], stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "held"
        assert main(_ablate(runs)) == 1
        line = _last_line(capsys.readouterr().err)
        assert line.startswith(f"gsbench ablate: error: {runs}: another process is writing this runs folder")
        assert f"pid {p.pid}" in line and "(the winner)" in line
        assert os.listdir(runs) == ["writer.lock"] and read_holder(runs)["pid"] == p.pid   # the winner's, untouched
    finally:
        p.kill()
        p.wait()


@pytest.mark.slow   # a second process that imports the grids (torch): ~10 s on 2 cores
def test_two_ablates_into_one_folder_the_winner_finishes_the_loser_exits_1(tmp_path, capsys):
    runs, gate = tmp_path / "runs", tmp_path / "gate"
    winner = subprocess.Popen([sys.executable, "-c", WINNER, str(gate), *_ablate(runs)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.time() + 120
        while not list(runs.glob("*/results.json")):
            assert winner.poll() is None, winner.communicate()
            assert time.time() < deadline, "the winner never started a cell"
            time.sleep(0.1)
        assert main(_ablate(runs)) == 1
        line = _last_line(capsys.readouterr().err)
        assert "another process is writing this runs folder" in line and f"pid {winner.pid}" in line
    finally:
        gate.write_text("go")
        out, err = winner.communicate(timeout=300)
    assert winner.returncode == 0, out[-2000:] + err[-2000:]
    assert "cells: done" in out and _litter(runs) == [] and not (runs / "writer.lock").exists()


def test_a_folder_of_someone_elses_files_is_refused_and_with_force_left_alone(tmp_path, capsys, monkeypatch):
    runs = tmp_path / "runs"
    runs.mkdir()
    (runs / "notes.txt").write_text("mine")
    assert main(_ablate(runs)) == 1
    line = _last_line(capsys.readouterr().err)
    assert "e.g. notes.txt" in line and "--force" in line and os.listdir(runs) == ["notes.txt"]
    argv = ["claims", "--quick", "--grids", CLAIM_GRIDS[0], "--out", str(runs), "--executor", "serial"]
    assert main(argv) == 1
    assert "e.g. notes.txt" in _last_line(capsys.readouterr().err) and os.listdir(runs) == ["notes.txt"]
    called = []
    monkeypatch.setattr(grids, "run_grid", lambda grid, out, *a, **k: called.append(out) or
                        grids.GridReport([], {}, [], []))
    assert main(_ablate(runs, "--force")) == 0
    assert called == [runs] and (runs / "notes.txt").read_text() == "mine"


def test_what_gsbench_puts_in_a_runs_folder_is_not_foreign(tmp_path):
    runs = tmp_path / "runs"
    for d in ("0123456789abcdef", "fedcba9876543210", "empty", "scenes/tabletop-small-s0", ".gsbench_cache",
              ".submitit", "report", ".report.staging-12-abc"):
        (runs / d).mkdir(parents=True)
    (runs / "0123456789abcdef" / "cell_status.json").write_text("{}")
    (runs / "fedcba9876543210" / "writer.lock").write_text("{}")
    for f in ("grid-tiny-test.json", "collected.parquet", "writer.lock", ".report.writer.lock", ".grid-x.json.a1.tmp"):
        (runs / f).write_text("x")
    assert foreign_entries(runs) == []
    (runs / "notes.txt").write_text("mine")
    (runs / "photos").mkdir()
    (runs / "photos" / "me.jpg").write_bytes(b"jpg")
    (runs / "link").symlink_to(runs / "scenes")
    assert foreign_entries(runs) == ["link", "notes.txt", "photos"]
