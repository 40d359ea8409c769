"""The runs behind tests/data/loop_golden/: every built-in method trained and evaluated on the tiny scene
with periodic evaluation, densification and checkpoints, so a change of the training loop shows.

    .venv/bin/python tests/support/loop_golden.py write              # the loop changed: this CPU's file, others dropped
    .venv/bin/python tests/support/loop_golden.py write --add-family # the loop unchanged: add this CPU family's file

tests/runs/test_loop_golden.py runs the same and compares, in two ways:
- exactly, every bit, against the file written on this CPU family (same model name and feature flags,
  gsbench.environment.cpu_facts), when there is one;
- within a stated tolerance over a short horizon (HORIZON steps of the training log, LOG_RTOL), against
  every family's file: what holds on any x86-64 CPU.

Why one file per CPU family. The runs happen in a child process under PORTABLE_ENV, which pins what
every x86-64 CPU can be told to compute alike: MKL's conditional numerical reproducibility in its
COMPATIBLE branch, PyTorch's DEFAULT capability, numba's generic target, numpy's and OpenCV's baseline
kernels. Without it the numbers move with the CPU within ten steps (MKL's products, PyTorch's
vectorised kernels: measured on an AVX-512 Intel Xeon). With it, an AMD EPYC (Zen 4) still differs
from the Intel Xeon that wrote the first file by one float32 ulp in the first ten steps (vanilla's
L_rec at step 10: 0.23697142601013182 against 0.23697144985198976), and the pinnings this machine
can vary do not move it (scripts/cpu_fingerprint.py bisect; docs/training.md). So bits are compared
only on the family that wrote them, and elsewhere the first HORIZON steps must agree within LOG_RTOL.
Measured between the two files: the logged losses of the first 20 steps differ by at most 1.4e-7
relative, the periodic evaluation's SSIM by 3e-8 (OpenCV), its PSNR not at all, and the thresholded
LERF mIoU by up to 2.4 % (one ulp flips a query's threshold).

History of the numbers (the loop unchanged each time unless said): the file was first written by the
commit before the harness took over the loop (the methods' own fit() loops), which the harness's loop
matched exactly. It was rewritten for the cpu rasterizer's vectorised exp and pixel sums (vanilla's
log within 1e-7 relative), the CPU SSIM loss in numba (loss totals within 4e-5 relative), the float32
exponential and GaussianDS's losses in numba (losses within 1.5e-4 relative), a CPU step's PyTorch ops
on one thread (grouping's reg3d within 7e-8 relative), and PORTABLE_ENV with the depth prior at its
estimator's working size (GaussianDS's L_depth up to 2 %). Since then one file per CPU family.

The runs use 2 threads, whatever the machine or the pytest-xdist worker count: training gives the
same bits for any thread count, but evaluation's PyTorch ops may not, and the files were written with 2.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch
from tiny import TINY_SCENE_ARGS, TINY_SET

from gsbench.cli import main
from gsbench.config import load_config
from gsbench.environment import cpu_facts
from gsbench.evaluation import evaluate_run
from gsbench.runs import train_run
from gsbench.store import read_jsonl

METHODS = ("vanilla", "twostage", "grouping", "gaussiands")
THREADS = 2
GOLDEN_DIR = Path(__file__).resolve().parents[1] / "data" / "loop_golden"
# What any x86-64 CPU must reproduce: the training log up to step HORIZON, each number within LOG_RTOL
# relative (an AMD EPYC and an Intel Xeon differ by one float32 ulp, 1e-7 relative, in the first ten
# steps); integers (Gaussian counts, densification counts, steps) exactly; periodic evaluations by
# PSNR and SSIM only.
HORIZON = 10
LOG_RTOL = 1e-5
# A mutation of the loop for tests/runs/test_loop_golden.py's slow test (none in normal runs): the
# child applies it before training, to show that the comparisons catch a one-line change.
MUTATION_ENV = "GSBENCH_GOLDEN_MUTATION"
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


def family() -> dict:
    """This machine's CPU family: model name and feature-flag hash (as `gsbench verify` compares them)."""
    facts = cpu_facts()
    return {"cpu_model": facts.get("cpu_model"), "cpu_flags": facts.get("cpu_flags")}


def family_file(fam: dict) -> Path:
    """The golden file of a CPU family: its model name as a slug, and its flag hash."""
    slug = re.sub(r"[^a-z0-9]+", "-", str(fam.get("cpu_model") or "unknown").lower()).strip("-")[:48]
    return GOLDEN_DIR / f"{slug}-{str(fam.get('cpu_flags') or 'noflags')[:8]}.json"


def goldens() -> dict[Path, dict]:
    """Every family's golden file: {path: {"written_on": family, "runs": {method: ...}}}."""
    return {p: json.loads(p.read_text()) for p in sorted(GOLDEN_DIR.glob("*.json"))}


def golden_runs(work: Path, methods: tuple[str, ...] = METHODS, mutation: str = "") -> dict:
    """{method: {"metrics": results.json metrics, "log": train_log.jsonl lines without wall times}},
    computed in a child process under PORTABLE_ENV (with `mutation` applied, for the mutation test)."""
    out = Path(work) / "golden_runs.json"
    env = {**os.environ, **PORTABLE_ENV, "GSBENCH_THREADS": str(THREADS), MUTATION_ENV: mutation}
    proc = subprocess.run([sys.executable, __file__, "--compute", str(out), str(work), ",".join(methods)], env=env,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"golden runs failed (exit {proc.returncode}):\n{proc.stderr[-4000:]}")
    return json.loads(out.read_text())


def _compute(work: Path, methods: tuple[str, ...]) -> dict:
    """The runs in this process (under PORTABLE_ENV: golden_runs starts it so)."""
    assert pinned(), "the golden runs need PORTABLE_ENV (golden_runs sets it)"
    torch.set_num_threads(THREADS)  # evaluation's; training's is GSBENCH_THREADS
    _mutate(os.environ.get(MUTATION_ENV, ""))
    return _golden_runs(work, methods)


def _mutate(name: str) -> None:
    """One-line changes of the loop that the golden test must catch (its slow mutation test)."""
    from gsbench.train import adam, losses
    if name == "adam_beta2":            # one Adam constant: beta2 0.999 -> 0.9995
        init = adam.Adam.__init__
        adam.Adam.__init__ = lambda self, params, lr=1e-3, betas=(0.9, 0.999), **k: init(
            self, params, lr, (betas[0], 0.9995), **k)
    elif name == "dssim_weight_ulp":      # L_rec's SSIM weight 0.2 one float32 ulp higher
        from gsbench.methods import vanilla
        rec, weight = losses.reconstruction_loss, float(np.nextafter(np.float32(0.2), np.float32(1.0)))
        vanilla.reconstruction_loss = lambda pred, gt, lambda_dssim=0.2: rec(pred, gt, weight)
    elif name:
        raise ValueError(f"unknown mutation {name!r}")


def _golden_runs(work: Path, methods: tuple[str, ...] = METHODS) -> dict:
    scene = work / "scene"
    assert main(["make-scene", *TINY_SCENE_ARGS, "--out", str(scene), "--quiet"]) == 0
    out = {}
    for m in methods:
        run = train_run(load_config(m, "cpu-small", SET), scene, work / m, progress=False)
        res = evaluate_run(run, progress=False)
        log = [{k: v for k, v in r.items() if k != "wall_s"} for r in read_jsonl(run / "train_log.jsonl")]
        metrics = {k: v for k, v in _numbers(res["metrics"]).items() if not k.startswith("fps")}
        out[m] = {"metrics": metrics, "log": log}
    return out


# ---------------------------------------------------------------------------- comparisons
# results.json names added after a golden was written: checked by their own tests, not here
ADDED_SINCE = {"ds_edge_fraction"}


def first_difference(got, want, path: str = "", rtol: float = 0.0) -> str | None:
    """The first path where two JSON trees differ, with both values; None when they are equal (floats
    within `rtol` relative; integers and strings always exactly)."""
    if isinstance(got, dict) and isinstance(want, dict):
        for k in sorted(set(got) | set(want)):
            if k not in got or k not in want:
                return f"{path}/{k}: only in {'golden' if k in want else 'this run'}"
            if d := first_difference(got[k], want[k], f"{path}/{k}", rtol):
                return d
        return None
    if isinstance(got, list) and isinstance(want, list):
        if len(got) != len(want):
            return f"{path}: {len(got)} entries, golden {len(want)}"
        for i, (a, b) in enumerate(zip(got, want)):
            if d := first_difference(a, b, f"{path}[{i}]", rtol):
                return d
        return None
    if isinstance(got, float) and isinstance(want, float) and rtol > 0:
        return None if abs(got - want) <= rtol * abs(want) else f"{path}: {got!r}, golden {want!r} (rtol {rtol:g})"
    return None if got == want else f"{path}: {got!r}, golden {want!r}"


def exact_differences(runs: dict, golden: dict) -> dict[str, str]:
    """{method: first difference} of every bit of the logs and metrics (the metrics the golden names)."""
    diffs = {}
    for method, want in golden.items():
        got = runs.get(method, {"metrics": {}, "log": []})
        extra = set(got["metrics"]) - set(want["metrics"]) - ADDED_SINCE
        metrics = {k: got["metrics"].get(k) for k in want["metrics"]}
        d = (f"/metrics: not in the golden: {sorted(extra)}" if extra
             else first_difference({"log": got["log"], "metrics": metrics}, want))
        if d:
            diffs[method] = d
    return diffs


def _short(log: list[dict]) -> list[dict]:
    """The log up to step HORIZON; periodic evaluations by PSNR and SSIM only (their thresholded LERF
    mIoU can flip a whole query for one ulp)."""
    out = []
    for r in log:
        if int(r.get("step", 0)) <= HORIZON:
            ev = r.get("eval")
            out.append(r if ev is None else {**r, "eval": {k: ev.get(k) for k in ("psnr", "ssim", "n_views")}})
    return out


def within_tolerance(runs: dict, golden: dict) -> dict[str, str]:
    """{method: first difference} of the log lines up to step HORIZON beyond LOG_RTOL (module docstring)."""
    diffs = {}
    for method, want in golden.items():
        got = runs.get(method, {"log": []})
        short = [_short(got["log"]), _short(want["log"])]
        if d := first_difference(short[0], short[1], "/log", LOG_RTOL):
            diffs[method] = d
    return diffs


def write(add_family: bool) -> None:
    """Write this CPU family's golden file. A changed loop (the default) drops every other family's file,
    which only its own CPU can write again; `add_family` keeps them, and first checks that this run
    agrees with each of them within the tolerance (so a family is added only for an unchanged loop)."""
    with tempfile.TemporaryDirectory() as d:
        runs = golden_runs(Path(d))
    others = {p: g for p, g in goldens().items() if p != family_file(family())}
    if add_family:
        bad = {p.name: d for p, g in others.items() if (d := within_tolerance(runs, g["runs"]))}
        if bad:
            sys.exit(f"not added: this run is outside the tolerance of {bad} "
                     "(the loop changed? write without --add-family)")
    else:
        for p in others:
            p.unlink()
            print(f"dropped {p.name} (another CPU family's; write it again there with --add-family)")
    path = family_file(family())
    GOLDEN_DIR.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"written_on": family(), "runs": runs}, indent=1, sort_keys=True) + "\n")
    counts = ", ".join(f"{m}: {len(v['metrics'])} metrics, {len(v['log'])} log lines" for m, v in runs.items())
    print(f"wrote {path}: {counts}")


if __name__ == "__main__":
    if sys.argv[1] == "--compute":
        methods = tuple(sys.argv[4].split(",")) if len(sys.argv) > 4 else METHODS
        Path(sys.argv[2]).write_text(json.dumps(_compute(Path(sys.argv[3]), methods)) + "\n")
        sys.exit(0)
    if sys.argv[1] != "write":
        sys.exit("usage: loop_golden.py write [--add-family]")
    write("--add-family" in sys.argv[2:])
