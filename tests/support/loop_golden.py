"""The runs behind tests/data/loop_golden.json: every built-in method trained and evaluated on the tiny
scene with periodic evaluation, densification and checkpoints, so a change of who owns the training
loop can be checked against what the code before it computed.

    .venv/bin/python tests/support/loop_golden.py tests/data/loop_golden.json   # writes the file

tests/runs/test_loop_golden.py runs the same and compares. The file was first written by the commit
before the harness took over the loop (the methods' own fit() loops), and the harness's loop matched
it exactly. It was rewritten, with the loop unchanged, when the cpu rasterizer's arithmetic changed
(its vectorised exp and pixel sums): vanilla's log then moved by at most 1e-7 relative, and on this
tiny scene the thresholded semantic metrics moved by up to 0.004 (absolute). It was rewritten again,
the loop unchanged, when the CPU SSIM loss moved from PyTorch convolutions to methods/ssim_cpu.py
(the same function; its last bits differ): the logged loss totals moved by at most 4e-5 relative,
PSNR by at most 0.002 dB, and on the tiny scene one of 21 LERF localisations flipped. It was
rewritten again, the loop unchanged, when the float32 cpu rasterizer took a float32 exponential
(within 1.01 ulp) and GaussianDS's depth, TV, L_sem and L_ds losses moved to methods/losses_cpu.py
(the same functions, summed in float64): logged losses moved by at most 1.5e-4 relative (TV,
grouping's reg3d), PSNR by at most 0.0006 dB, SSIM by at most 8e-4 relative, and on the tiny scene
the thresholded LERF metrics by up to 0.002 mIoU, with one of 42 localisations flipped. It was
rewritten again, the loop unchanged, when the trainer began running a CPU step's PyTorch ops on one
thread (gsbench/render/threads.py): vanilla's, twostage's and GaussianDS's runs kept every bit;
grouping's, whose classifier's products and regulariser's sums PyTorch had split over two threads,
moved in its reg3d term from step 15 by 7e-8 relative, its periodic eval SSIM by 3e-10 and its
depth AbsRel by 2e-9 relative.

The runs use 2 threads, whatever the machine or the pytest-xdist worker count: training gives the
same bits for any thread count, but evaluation's PyTorch ops may not, and the file was written with 2.
"""
from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

import torch
from tiny import TINY_SCENE_ARGS, TINY_SET

from gsbench.cli import main
from gsbench.config import load_config
from gsbench.evaluation import evaluate_run
from gsbench.runs import train_run
from gsbench.store import read_jsonl

METHODS = ("vanilla", "twostage", "grouping", "gaussiands")
THREADS = 2
SET = [*TINY_SET, "train.eval_every=10", "train.eval_views=2", "train.checkpoint_every=10",
       "twostage.semantic_iterations=10"]


def _numbers(d: dict) -> dict:
    return {k: v for k, v in d.items() if isinstance(v, (int, float)) and not isinstance(v, bool) or v is None}


def golden_runs(work: Path) -> dict:
    """{method: {"metrics": results.json metrics, "log": train_log.jsonl lines without wall times}}."""
    before_env, before = os.environ.get("GSBENCH_THREADS"), torch.get_num_threads()
    os.environ["GSBENCH_THREADS"] = str(THREADS)  # training's thread count
    torch.set_num_threads(THREADS)  # evaluation's
    try:
        return _golden_runs(work)
    finally:
        torch.set_num_threads(before)
        if before_env is None:
            os.environ.pop("GSBENCH_THREADS", None)
        else:
            os.environ["GSBENCH_THREADS"] = before_env


def _golden_runs(work: Path) -> dict:
    scene = work / "scene"
    assert main(["make-scene", *TINY_SCENE_ARGS, "--out", str(scene), "--quiet"]) == 0
    out = {}
    for m in METHODS:
        run = train_run(load_config(m, "cpu-small", SET), scene, work / m, progress=False)
        res = evaluate_run(run, progress=False)
        log = [{k: v for k, v in r.items() if k != "wall_s"} for r in read_jsonl(run / "train_log.jsonl")]
        metrics = {k: v for k, v in _numbers(res["metrics"]).items() if not k.startswith("fps")}
        out[m] = {"metrics": metrics, "log": log}
    return out


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as d:
        data = golden_runs(Path(d))
    Path(sys.argv[1]).write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    counts = ", ".join(f"{m}: {len(v['metrics'])} metrics, {len(v['log'])} log lines" for m, v in data.items())
    print(f"wrote {sys.argv[1]}: {counts}")
