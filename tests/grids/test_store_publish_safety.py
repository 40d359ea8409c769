"""Publishing under stress, on a tiny plan (two vanilla cells of 3 steps): two publishes at once (the
first slowed while it holds the store's lock) leave a store that reads whole, the second refused in
one line; a publish SIGKILLed at any step of its write leaves the old store or the new one, never a
mix, and the next publish completes it and removes what the killed one left beside the store.

Each publish under test runs in a subprocess (tests/grids/publish_hook.py) that wraps the file
operations of gsbench.grids.store_write: it pauses at the start of the write, or kills itself at the
N-th file operation (a rename, link or unlink) of the write."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
import yaml
from tiny_store import TINY_GRID

from gsbench import grids
from gsbench.cli import main
from gsbench.grids.executors import SerialExecutor
from gsbench.grids.store import read_store
from gsbench.grids.store_write import SCRATCH_MARK

HOOK = Path(__file__).with_name("publish_hook.py")
GRID = TINY_GRID


@pytest.fixture(scope="module")
def tiny_plan():
    """(grid file, runs folder with both cells finished, runs folder with the first one only)."""
    root = Path(tempfile.mkdtemp(prefix="gsbench-publish-safety-"))
    grid_file = root / "tiny.yaml"
    grid_file.write_text(yaml.safe_dump(GRID, sort_keys=False))
    runs = root / "runs"
    grids.run_grid(grids.load_grid(grid_file), runs, SerialExecutor(progress=False), log=lambda s: None)
    first = root / "first"
    shutil.copytree(runs, first)
    shutil.rmtree(sorted(p.parent for p in first.glob("*/results.json"))[1])
    yield grid_file, runs, first
    shutil.rmtree(root, ignore_errors=True)


def _publish(runs: Path, store: Path, grid_file: Path) -> list[str]:
    return ["publish", str(runs), "--to", str(store), "--grids", str(grid_file)]


def _state(store: Path) -> dict[str, str]:
    """Every cell of the store, read whole (each of its shared parts found and checked), as text."""
    return {c.run_id: json.dumps(c.record, sort_keys=True) for c in read_store(store)}


def _hooked(mode: str, n: int, marker: Path, argv: list[str]) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, str(HOOK), mode, str(n), str(marker), *argv],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _old_store(tiny_plan, folder: Path) -> Path:
    grid_file, _, first = tiny_plan
    store = folder / "store"
    assert main(_publish(first, store, grid_file)) == 0
    return store


def test_two_publishes_at_once_leave_a_whole_store(tiny_plan, tmp_path, capsys):
    grid_file, runs, _ = tiny_plan
    store = _old_store(tiny_plan, tmp_path / "s")
    old = _state(store)
    marker = tmp_path / "first.holding"
    proc = _hooked("pause", 0, marker, _publish(runs, store, grid_file))
    t0 = time.time()
    while not marker.exists():
        assert proc.poll() is None, f"the first publish ended early: {proc.communicate()}"
        assert time.time() - t0 < 300, "the first publish never reached its write"
        time.sleep(0.1)
    # the first holds the lock, its write pending: the store reads as the old one, a second writer is refused
    assert _state(store) == old
    capsys.readouterr()
    for argv in (_publish(runs, store, grid_file), ["publish", "--upgrade", str(store), "--grids", str(grid_file)]):
        assert main(argv) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "another process is writing this results store" in err[0]
    marker.with_suffix(".go").write_text("")
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert "1 cells added" in out
    new = _state(store)
    assert len(new) == 2 and all(new[k] == v for k, v in old.items())
    assert main(["publish", "--status", str(store), "--grids", str(grid_file)]) == 0
    assert "2 published cells: 2 current, 0 stale" in capsys.readouterr().out
    assert main(_publish(runs, store, grid_file)) == 0
    assert "2 already published" in capsys.readouterr().out
    assert sorted(os.listdir(tmp_path / "s")) == ["store"]


@pytest.mark.slow
def test_a_publish_killed_at_any_step_leaves_the_old_or_the_new_store(tiny_plan, tmp_path, capsys):
    grid_file, runs, _ = tiny_plan
    base = _old_store(tiny_plan, tmp_path / "base")
    old = _state(base)
    counted = tmp_path / "count" / "store"
    shutil.copytree(base, counted)
    marker = tmp_path / "count.calls"
    proc = _hooked("count", 0, marker, _publish(runs, counted, grid_file))
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    steps = int(marker.with_suffix(".calls").read_text())
    new = _state(counted)
    assert len(new) == 2 and new != old
    outcomes = {}
    for n in sorted({1, steps // 3, steps // 2, steps - 4, steps - 2, steps}):
        store = tmp_path / f"kill{n}" / "store"
        shutil.copytree(base, store)
        proc = _hooked("kill", n, tmp_path / f"kill{n}.m", _publish(runs, store, grid_file))
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == -signal.SIGKILL, f"step {n} of {steps}: exit {proc.returncode}: {err}"
        now = _state(store)
        assert now in (old, new), f"killed at step {n} of {steps}: neither the old nor the new store"
        outcomes[n] = "new" if now == new else "old"
        # the next publish completes the store and removes what the killed one left beside it
        assert main(_publish(runs, store, grid_file)) == 0
        assert _state(store) == new and not (store / SCRATCH_MARK).exists()
        assert sorted(os.listdir(store.parent)) == ["store"], f"left beside the store: {os.listdir(store.parent)}"
    capsys.readouterr()
    with capsys.disabled():
        print(f"\nkilled at step N of {steps}: store read as {outcomes}")
    assert set(outcomes.values()) == {"old", "new"}, outcomes       # kills before and after the swap both ran
