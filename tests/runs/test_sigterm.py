"""SIGTERM during `gsbench train` (a scheduler or `kill` stopping it) is handled as Ctrl-C is: the
step under way ends and is checkpointed, status.json says "interrupted", the command prints one line
and exits 143 (128 + SIGTERM); the same command resumes the run to the end."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from gsbench.store import load_torch, read_json, read_jsonl

ITERATIONS = 150


def _train(scene: Path, out: Path) -> subprocess.Popen:
    exe = Path(sys.executable).parent / "gsbench"
    args = [str(exe), "train", "--method", "vanilla", "--preset", "cpu-small", "--scene", str(scene), "--out", str(out),
            "--set", f"train.iterations={ITERATIONS}", "--set", "train.eval_every=0", "--set", "train.log_every=1",
            "--set", "train.checkpoint_every=0", "--no-progress"]
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "GSBENCH_THREADS": "1"})


def test_sigterm_checkpoints_says_interrupted_exits_143_and_resumes(tiny_scene, tmp_path):
    run = tmp_path / "run"
    proc = _train(tiny_scene, run)
    deadline = time.time() + 120
    while not (run / "train_log.jsonl").exists() and proc.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=120)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert proc.returncode == 143, err
    assert "Traceback" not in err and "Fatal Python error" not in err
    assert lines[-1] == "gsbench train: terminated (SIGTERM); finished work is saved, re-run to resume"
    st = read_json(run / "status.json")
    assert st["state"] == "interrupted" and "SIGTERM" in st["message"]
    step = load_torch(run / "checkpoint.pt")["step"]
    logged = max(int(r["step"]) for r in read_jsonl(run / "train_log.jsonl"))
    assert 1 <= logged <= step < ITERATIONS        # the checkpoint is the step the signal ended, not an older one
    assert not (run / "model.pt").exists()

    again = _train(tiny_scene, run)
    out, err = again.communicate(timeout=600)
    assert again.returncode == 0, err
    assert read_json(run / "status.json")["state"] == "done"
    steps = [int(r["step"]) for r in read_jsonl(run / "train_log.jsonl") if "loss" in r]
    assert steps == list(range(1, ITERATIONS + 1))      # resumed where it stopped: no step twice, none missing
