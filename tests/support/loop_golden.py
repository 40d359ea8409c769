"""The runs behind tests/data/loop_golden.json: every built-in method trained and evaluated on the tiny
scene with periodic evaluation, densification and checkpoints, so a change of who owns the training
loop can be checked against what the code before it computed.

    .venv/bin/python tests/support/loop_golden.py tests/data/loop_golden.json   # writes the file

tests/runs/test_loop_golden.py runs the same and compares. The file was first written by the commit
before the harness took over the loop (the methods' own fit() loops), and the harness's loop matched
it exactly. It was rewritten, with the loop unchanged, when the cpu rasterizer's arithmetic changed
(its vectorised exp and pixel sums): vanilla's log then moved by at most 1e-7 relative, and on this
tiny scene the thresholded semantic metrics moved by up to 0.004 (absolute). It was rewritten again,
the loop unchanged, when the CPU SSIM loss moved from PyTorch convolutions to gsbench/train/ssim_cpu.py
(the same function; its last bits differ): the logged loss totals moved by at most 4e-5 relative,
PSNR by at most 0.002 dB, and on the tiny scene one of 21 LERF localisations flipped. It was
rewritten again, the loop unchanged, when the float32 cpu rasterizer took a float32 exponential
(within 1.01 ulp) and GaussianDS's depth, TV, L_sem and L_ds losses moved to gsbench/train/losses_cpu.py
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

The runs happen in a child process under PORTABLE_ENV, so that the file holds the same bits on any
x86-64 CPU. Without it the numbers depend on the CPU that runs them: MKL picks its matrix-product
kernels by CPU (grouping's classifier, the autoencoder, the latent decoders: a one-ulp difference at
step 10 of GaussianDS on an AVX-512 Intel Xeon against the machine that wrote the file, which the
thresholded LERF metrics amplified to 0.05 in localisation accuracy), PyTorch its vectorised kernels
(AVX-512 against AVX2 moved grouping's reg3d at step 5), and numba, numpy and OpenCV their SIMD paths.
PORTABLE_ENV pins each to the code every x86-64 CPU runs: MKL's conditional numerical reproducibility
in its COMPATIBLE branch, PyTorch's DEFAULT capability, numba's generic target, numpy's and OpenCV's
baseline kernels. It was rewritten under that environment for this reason (the loop unchanged):
vanilla's and twostage's losses kept every bit and their periodic-eval SSIM moved by 3e-8 relative
(OpenCV's baseline filter); grouping's losses moved by about 1e-7 relative (MKL's products); and
GaussianDS's by up to 2 % in L_depth, since the same change gave the simulated depth prior its
estimator's working size (gsbench/priors/depth.py), with PSNR +0.001 dB and LERF mIoU -0.0001.
"""
from __future__ import annotations

import json
import os
import subprocess
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


# What every x86-64 CPU computes alike (module docstring); set before the child imports torch.
PORTABLE_ENV = {
    "MKL_CBWR": "COMPATIBLE",                 # MKL: the same kernels on every x86 CPU
    "ATEN_CPU_CAPABILITY": "default",         # PyTorch: no AVX2 / AVX-512 kernels
    "NUMBA_CPU_NAME": "generic",              # numba: compile for the generic x86-64 target
    "NPY_DISABLE_CPU_FEATURES": "X86_V3,X86_V4,AVX512_ICL,AVX512_SPR",   # numpy: baseline kernels only
    "OPENCV_CPU_DISABLE": "SSE4.1,SSE4.2,AVX,FP16,AVX2,AVX512-SKX,POPCNT",  # OpenCV: baseline kernels only
}


def pinned() -> bool:
    """This process runs under PORTABLE_ENV."""
    return all(os.environ.get(k) == v for k, v in PORTABLE_ENV.items())


def golden_runs(work: Path) -> dict:
    """{method: {"metrics": results.json metrics, "log": train_log.jsonl lines without wall times}},
    computed in a child process under PORTABLE_ENV."""
    out = Path(work) / "golden_runs.json"
    env = {**os.environ, **PORTABLE_ENV, "GSBENCH_THREADS": str(THREADS)}
    proc = subprocess.run([sys.executable, __file__, "--compute", str(out), str(work)], env=env,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"golden runs failed (exit {proc.returncode}):\n{proc.stderr[-4000:]}")
    return json.loads(out.read_text())


def _compute(work: Path) -> dict:
    """The runs in this process (under PORTABLE_ENV: golden_runs starts it so)."""
    assert pinned(), "the golden runs need PORTABLE_ENV (golden_runs sets it)"
    torch.set_num_threads(THREADS)  # evaluation's; training's is GSBENCH_THREADS
    return _golden_runs(work)


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
    if sys.argv[1] == "--compute":
        Path(sys.argv[2]).write_text(json.dumps(_compute(Path(sys.argv[3]))) + "\n")
        sys.exit(0)
    with tempfile.TemporaryDirectory() as d:
        data = golden_runs(Path(d))
    Path(sys.argv[1]).write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    counts = ", ".join(f"{m}: {len(v['metrics'])} metrics, {len(v['log'])} log lines" for m, v in data.items())
    print(f"wrote {sys.argv[1]}: {counts}")
