"""One writer per run folder: a live holder refuses a second writer, a killed one is taken over."""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gsbench.runlock import LOCK_FILE, RunLock, RunLockedError, read_holder

HOLD = """
import sys, time
from gsbench.runlock import RunLock
lock = RunLock(sys.argv[1], command="holder-under-test").acquire()
print("held", flush=True)
time.sleep(120)
"""


def _start_holder(run_dir: Path) -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, "-c", HOLD, str(run_dir)], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "held"
    return p


def test_a_live_holder_refuses_a_second_writer_and_a_killed_one_is_taken_over(tmp_path):
    run = tmp_path / "run"
    p = _start_holder(run)
    try:
        holder = read_holder(run)
        assert holder["pid"] == p.pid and holder["host"] == socket.gethostname()
        assert holder["command"] == "holder-under-test" and holder["started"] <= time.time()
        with pytest.raises(RunLockedError) as e:
            RunLock(run).acquire()
        msg = str(e.value)
        assert "\n" not in msg and f"pid {p.pid} on {socket.gethostname()}" in msg and "holder-under-test" in msg
        os.kill(p.pid, signal.SIGKILL)
        time.sleep(0.3)                       # not reaped yet: a zombie, which must count as dead
        with RunLock(run, command="next") as lock:
            assert lock.took_over["pid"] == p.pid
            assert read_holder(run)["pid"] == os.getpid() and read_holder(run)["command"] == "next"
        assert not (run / LOCK_FILE).exists()   # released
    finally:
        p.kill()
        p.wait()


def test_the_same_process_may_nest_and_only_the_outer_release_unlocks(tmp_path):
    run = tmp_path / "run"
    with RunLock(run, command="outer"):
        with RunLock(run, command="inner"):
            assert read_holder(run)["command"] == "outer"
        assert read_holder(run)["command"] == "outer"
    assert read_holder(run) is None


def test_a_lock_of_another_host_is_stale_only_when_it_stopped_refreshing(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / LOCK_FILE).write_text(json.dumps({"pid": 1, "host": "other-node", "started": time.time(), "command": "x"}))
    with pytest.raises(RunLockedError, match="pid 1 on other-node"):
        RunLock(run, stale_after_s=60).acquire()
    old = time.time() - 600
    os.utime(run / LOCK_FILE, (old, old))
    with RunLock(run, stale_after_s=60) as lock:
        assert lock.took_over["host"] == "other-node"


def test_a_requeued_grid_cell_takes_over_the_lock_of_its_killed_worker(tmp_path, monkeypatch):
    from gsbench.grids import running
    run = tmp_path / "runs" / "cell1"
    p = _start_holder(run)
    calls = []
    monkeypatch.setattr(running, "_train_and_evaluate", lambda spec, run_dir, status: calls.append(run_dir))
    spec = {"run_dir": str(run), "scene_path": "x", "config": {}, "study": "s", "axes": {}, "scene": {"path": "x"},
            "seed": 0, "method": "vanilla"}
    try:
        out = running.run_cell(spec)
        assert out["state"] == "locked" and f"pid {p.pid}" in out["error"] and calls == []
        assert not (run / "cell_status.json").exists()          # nothing written next to a live writer
        os.kill(p.pid, signal.SIGKILL)
        p.wait()
        out = running.run_cell(spec)
        assert out["state"] == "done" and calls == [run]
        assert read_holder(run) is None
    finally:
        p.kill()
        p.wait()
