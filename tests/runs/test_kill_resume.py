"""Interrupting training loses nothing already written, and a re-run resumes; non-finite training stops cleanly.

These start the real `gsbench` executable as a subprocess, interrupt it (SIGINT, then SIGKILL) right
after it wrote a checkpoint, re-run the same command and check the run folder is complete and valid.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Optional

import numpy as np
import pytest
import torch

from gsbench.cli import main
from gsbench.store import load_torch, read_json

EXE = str(Path(sys.executable).parent / "gsbench")
ITERS = 100     # room for two kills after checkpoints 20..80 (s1 < s2 < ITERS) even when one is detected late
CKPT_EVERY = 20
LOG_EVERY = 5


@pytest.fixture(scope="module")
def workspace(tiny_scene, tmp_path_factory) -> Path:
    """A copy of the session's tiny scene; every run of this module lives next to it and shares the priors cache."""
    root = tmp_path_factory.mktemp("killresume")
    shutil.copytree(tiny_scene, root / "scene")
    return root


def train_args(scene: Path, out: Path, *sets: str) -> list[str]:
    args = ["train", "--method", "gaussiands", "--scene", str(scene), "--preset", "cpu-small", "--out", str(out),
            "--no-progress", "--set", "semantic.autoencoder.epochs=10"]   # not 500: ~2.5 s saved per process
    for s in sets:
        args += ["--set", s]
    return args


def train_cmd(scene: Path, out: Path, *sets: str) -> list[str]:
    return [EXE, *train_args(scene, out, *sets)]


def checkpoint_step(run: Path) -> int:
    p = run / "checkpoint.pt"
    if not p.exists():
        return -1
    return int(load_torch(p)["step"])


def own_status(run: Path, started: float) -> Optional[dict]:
    """status.json when the process started at `started` has written it (its time is later), else None."""
    try:
        st = read_json(run / "status.json")
    except (OSError, ValueError):
        return None
    return st if float(st.get("time", 0.0)) >= started else None


def start_and_interrupt(cmd: list[str], run: Path, sig: int, log: Path, timeout: float = 900) -> int:
    """Start `cmd`, wait until this process has written its own "running" status and then a checkpoint
    newer than any the folder held when it started, send `sig`; return that checkpoint's step.

    Waiting for the process's own status first matters on a resumed run: the previous run's Ctrl-C
    already wrote a checkpoint newer than the one the test last read, so a wait for "a newer checkpoint"
    alone could kill the new process before it wrote anything (seen under a loaded parallel suite)."""
    before = checkpoint_step(run)
    started = time.time()
    with open(log, "w") as f:
        # SIGINT back to its default in the child: a shell that starts the test run in the background
        # leaves it ignored, Python then keeps it ignored, and Ctrl-C could not be tested
        proc = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, start_new_session=True,
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        t0 = time.time()
        while True:
            st = own_status(run, started)
            step = checkpoint_step(run)
            if st is not None and st["state"] == "running" and step > before:
                break
            if proc.poll() is not None:
                pytest.fail(f"training ended (exit {proc.returncode}) before a checkpoint past step {before}:\n"
                            + log.read_text()[-2000:])
            if time.time() - t0 > timeout:
                pytest.fail("no checkpoint within the time limit")
            time.sleep(0.05)
        os.killpg(proc.pid, sig)
        proc.wait(timeout=120)
    finally:
        if proc.poll() is None:   # only our own process group
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    if sig == signal.SIGKILL:
        assert proc.returncode == -signal.SIGKILL
    else:
        assert proc.returncode == 130, log.read_text()[-2000:]
        assert "interrupted" in log.read_text()
    return step


def loss_lines(run: Path) -> list[dict]:
    """Every line of train_log.jsonl must be complete JSON (no torn lines after a kill + resume)."""
    lines = (run / "train_log.jsonl").read_text().splitlines()
    out = [json.loads(ln) for ln in lines if ln.strip()]
    return [r for r in out if "loss" in r]


@pytest.mark.slow
def test_sigint_then_sigkill_then_resume_gives_a_complete_run(workspace, tmp_path):
    scene, run = workspace / "scene", workspace / "run_kill"
    cmd = train_cmd(scene, run, f"train.iterations={ITERS}", f"train.checkpoint_every={CKPT_EVERY}",
                    f"train.log_every={LOG_EVERY}", "train.eval_every=100")

    # 1) Ctrl-C right after the first checkpoint: exit 130, status says interrupted, checkpoint kept
    s1 = start_and_interrupt(cmd, run, signal.SIGINT, tmp_path / "a.log")
    assert 0 < s1 < ITERS
    st = read_json(run / "status.json")
    assert st["state"] == "interrupted" and "interrupted" in st["message"]
    k1 = checkpoint_step(run)            # s1, or the checkpoint the Ctrl-C itself wrote
    assert s1 <= k1 < ITERS
    run_id = read_json(run / "config.json")["run_id"]

    # 2) re-run, SIGKILL right after it wrote a checkpoint of its own; it resumed from k1, not from 0
    s2 = start_and_interrupt(cmd, run, signal.SIGKILL, tmp_path / "b.log")
    assert k1 < s2 < ITERS
    assert f"from its checkpoint at step {k1} of {ITERS}" in (tmp_path / "b.log").read_text()
    assert read_json(run / "status.json")["state"] == "running"      # killed: nothing could update it
    k2 = checkpoint_step(run)
    before = [r for r in loss_lines(run) if r["step"] <= k2]

    # 3) re-run to the end, from the killed run's last checkpoint
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert f"from its checkpoint at step {k2} of {ITERS}" in proc.stderr

    st = read_json(run / "status.json")
    assert st["state"] == "done" and st["message"] == ""
    assert read_json(run / "config.json")["run_id"] == run_id
    ck = load_torch(run / "checkpoint.pt")
    assert ck["step"] == ITERS
    assert all(bool(torch.isfinite(v).all()) for v in ck["params"].values())
    summary = read_json(run / "train_summary.json")
    assert summary["status"] == "done" and summary["iterations"] == ITERS
    for name in ("env.json", "config.json"):
        assert isinstance(read_json(run / name), dict)

    rows = loss_lines(run)
    steps = [r["step"] for r in rows]
    # every logged step exactly once: the resumed runs continued from their checkpoint instead of
    # starting again from 0 (which would repeat steps) or skipping ahead
    assert steps == list(range(LOG_EVERY, ITERS + 1, LOG_EVERY))
    # what was written before the kill up to the checkpoint is kept as it was
    assert [r for r in rows if r["step"] <= k2] == before
    assert all(np.isfinite(r["loss"]["total"]) for r in rows)

    # the finished run loads and evaluates into a valid results.json
    from gsbench.evaluation.trained_run import load_run
    method, cfg, _ = load_run(run)
    assert cfg["run_id"] == run_id and method.field.num > 0
    assert main(["eval", str(run), "--no-progress"]) == 0    # in-process: the run, not the CLI start, is under test
    res = read_json(run / "results.json")
    assert res["status"] == "done" and res["run_id"] == run_id
    assert res["metrics"]["psnr"] is not None and np.isfinite(res["metrics"]["psnr"])


# The non-finite tests call the CLI's main() in this process (the same exit code and stderr as the
# executable, without a ~3.5 s interpreter start each); the tests above run `gsbench train` as a process.
@pytest.mark.slow
def test_nonfinite_training_stops_with_status_and_keeps_last_good_checkpoint(workspace, capsys):
    """A colour learning rate of 1e36 makes step 1 finite (colours ~1e36) and the step-2 loss overflow (its
    L1 term sums thousands of float32 values near 1e36)."""
    scene, run = workspace / "scene", workspace / "run_nonfinite"
    args = train_args(scene, run, "train.iterations=20", "train.checkpoint_every=1", "train.eval_every=0",
                      "train.lr.color=1e36")
    t0 = time.time()
    rc = main(args)
    assert time.time() - t0 < 600                                      # stopped, did not hang
    assert rc == 1
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert lines[-1].startswith("gsbench train: error: non-finite loss at step 2")
    assert "Traceback" not in err
    st = read_json(run / "status.json")
    assert st["state"] == "nonfinite" and "non-finite loss at step 2" in st["message"]
    assert read_json(run / "train_summary.json")["status"] == "nonfinite"
    assert not (run / "model.pt").exists()                             # no silent NaN model
    ck = load_torch(run / "checkpoint.pt")                             # the last good checkpoint
    assert ck["step"] == 1
    assert all(bool(torch.isfinite(v).all()) for v in ck["params"].values())


@pytest.mark.slow
@pytest.mark.parametrize("poison, expect", [
    ("gaussiands.lambdas.tv=1e40", "non-finite loss at step 1"),              # inf in float32
    ("train.lr.opacity=1e38", "optimiser step overflowed at step 1"),         # Adam: lr / (1 - beta1) > float32 max
])
def test_nonfinite_at_the_first_step_is_a_clear_status(workspace, poison, expect, capsys):
    run = workspace / ("run_" + poison.split("=")[0].replace(".", "_"))
    assert main(train_args(workspace / "scene", run, "train.iterations=20", "train.eval_every=0", poison)) == 1
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert lines[-1].startswith(f"gsbench train: error: {expect}") and "Traceback" not in err
    assert lines[-1].endswith("no checkpoint was written before this step")
    st = read_json(run / "status.json")
    assert st["state"] == "nonfinite" and expect in st["message"]
    assert not (run / "model.pt").exists() and not (run / "checkpoint.pt").exists()


@pytest.mark.slow
def test_a_second_train_into_a_running_folder_is_refused_and_a_sigkilled_holder_is_taken_over(workspace, tmp_path):
    """One writer per run folder: while a `gsbench train` writes a folder, the same command into it exits 1
    with one line naming the holder (and writes nothing); after a SIGKILL of the holder the next run takes
    the lock over and finishes the run."""
    run = tmp_path / "run"
    # 60 steps: the holder is stopped right after its first checkpoint (20), 40 steps before its end
    cmd = train_cmd(workspace / "scene", run, "train.iterations=60", f"train.checkpoint_every={CKPT_EVERY}",
                    f"train.log_every={LOG_EVERY}")
    log = tmp_path / "first.log"
    with open(log, "w") as f:
        first = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        t0 = time.time()
        while checkpoint_step(run) < 0:
            assert first.poll() is None, log.read_text()[-2000:]
            assert time.time() - t0 < 600, "no checkpoint within the time limit"
            time.sleep(0.1)
        os.killpg(first.pid, signal.SIGSTOP)          # keep it mid-run (alive) while the second one starts
        log_lines = (run / "train_log.jsonl").read_text().count("\n")
        second = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        assert second.returncode == 1, second.stderr
        err = second.stderr.strip().splitlines()
        assert len(err) == 1 and "another process is writing this run folder" in err[0], second.stderr
        assert f"pid {first.pid} on " in err[0] and "gsbench train" in err[0]
        assert (run / "train_log.jsonl").read_text().count("\n") == log_lines      # the second wrote nothing
        os.killpg(first.pid, signal.SIGKILL)
        first.wait(timeout=60)
    finally:
        if first.poll() is None:
            os.killpg(first.pid, signal.SIGKILL)
            first.wait()
    assert json.loads((run / "writer.lock").read_text())["pid"] == first.pid      # left behind by the kill
    third = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert third.returncode == 0, third.stderr[-2000:]
    assert "took over the lock of a stale writer" in third.stderr and f"pid {first.pid}" in third.stderr
    assert read_json(run / "status.json")["state"] == "done"
    assert not (run / "writer.lock").exists()
