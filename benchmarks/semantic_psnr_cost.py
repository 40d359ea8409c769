"""Benchmark: the PSNR GaussianDS's joint semantics cost against vanilla 3DGS, seed by seed.

    .venv/bin/python benchmarks/semantic_psnr_cost.py [--scene DIR] [--preset cpu-medium] [--seeds 0 1 2]
                                                      [--set KEY=VALUE ...] [--both KEY=VALUE ...]
                                                      [--work DIR] [--json out.json]

Trains `vanilla` and `gaussiands` (d = 3 unless `--set semantic.latent_dim=...`) with `gsbench train` at
each seed on one scene, evaluates them with `gsbench eval`, and prints per seed and over the seeds
GaussianDS - vanilla PSNR with a paired 95 % t interval (Student's t on the per-seed differences; no
interval with fewer than two seeds). `--set` applies to GaussianDS only (a candidate fix, e.g.
`--set gaussiands.sem_geometry=detached`); `--both` to both methods.

Without `--scene` a tabletop-medium scene (seed 0) is generated in the work folder. For a real
capture, pass its folder and its preset and what its labels need, e.g.
`--scene DTU_SCAN37 --preset cpu-real --set priors.masks.provider=gt priors.depth.provider=sfm`.
Run folders are named by method, overrides and seed under --work (default: a fresh temporary folder)
and reused when already evaluated, so a second call with another `--set` retrains only GaussianDS.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

from scipy.stats import t as student_t

GSBENCH = [sys.executable, "-c", "import sys; from gsbench.cli import main; sys.exit(main())"]
METRICS = ("psnr", "ssim", "miou_3dovs")


def _run(cmd: list[str], log: Path) -> None:
    """Run a gsbench command niced, its output in `log`; exit with the log's tail when it fails."""
    print(f"  $ {' '.join(cmd[3:])}", file=sys.stderr, flush=True)
    r = subprocess.run(["nice", "-n", "10", *cmd], capture_output=True, text=True)
    log.write_text(r.stdout + "\n--- stderr ---\n" + r.stderr)
    if r.returncode != 0:
        raise SystemExit(f"semantic_psnr_cost: {' '.join(cmd[3:])} failed (exit {r.returncode}); see {log}\n"
                         f"{r.stderr[-2000:]}")


def _tag(method: str, sets: list[str]) -> str:
    digest = hashlib.sha256("\n".join(sets).encode()).hexdigest()[:8] if sets else "defaults"
    return f"{method}-{digest}"


def train_and_eval(method: str, scene: Path, preset: str, seed: int, sets: list[str], work: Path) -> dict:
    """The run's metrics (results.json `metrics`), trained and evaluated unless already there."""
    run = work / f"{_tag(method, sets)}-s{seed}"
    results = run / "results.json"
    if not results.exists():
        over = [f"seed={seed}", *sets]
        _run([*GSBENCH, "-q", "train", "--method", method, "--scene", str(scene), "--preset", preset,
              "--set", *over, "--out", str(run), "--no-progress"], work / f"{run.name}.train.log")
        _run([*GSBENCH, "-q", "eval", str(run), "--no-progress"], work / f"{run.name}.eval.log")
    try:
        metrics = json.loads(results.read_text())["metrics"]
    except (OSError, ValueError, KeyError) as e:
        raise SystemExit(f"semantic_psnr_cost: {results}: no metrics ({e})") from None
    if not isinstance(metrics.get("psnr"), (int, float)):
        raise SystemExit(f"semantic_psnr_cost: {results}: no PSNR")
    return {k: metrics.get(k) for k in METRICS}


def paired_interval(diffs: list[float], level: float = 0.95) -> tuple[float, float | None, float | None]:
    """(mean, low, high) of the per-seed differences: Student's t with n - 1 degrees of freedom;
    low and high are None with fewer than two values (no spread to read)."""
    n = len(diffs)
    if n == 0:
        raise ValueError("no differences")
    mean = sum(diffs) / n
    if n < 2:
        return mean, None, None
    sd = math.sqrt(sum((d - mean) ** 2 for d in diffs) / (n - 1))
    half = float(student_t.ppf(0.5 + level / 2, n - 1)) * sd / math.sqrt(n)
    return mean, mean - half, mean + half


def _fmt(x) -> str:
    return "n/a" if x is None else f"{x:.3f}"


def table(rows: list[dict], label: str) -> str:
    lines = [f"GaussianDS ({label}) - vanilla", "",
             "| seed | vanilla PSNR | GaussianDS PSNR | difference dB | vanilla SSIM | GaussianDS SSIM | "
             "GaussianDS 3D-OVS mIoU |", "|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        v, g = r["vanilla"], r["gaussiands"]
        lines.append(f"| {r['seed']} | {v['psnr']:.2f} | {g['psnr']:.2f} | {g['psnr'] - v['psnr']:+.2f} | "
                     f"{_fmt(v['ssim'])} | {_fmt(g['ssim'])} | {_fmt(g['miou_3dovs'])} |")
    mean, low, high = paired_interval([r["gaussiands"]["psnr"] - r["vanilla"]["psnr"] for r in rows])
    ci = "no interval (n < 2)" if low is None else f"95 % t interval [{low:+.2f}, {high:+.2f}]"
    lines += ["", f"GaussianDS - vanilla PSNR: {mean:+.2f} dB, {ci}, n = {len(rows)} seeds (paired)"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default=None, help="scene folder (default: tabletop-medium generated in --work)")
    ap.add_argument("--preset", default="cpu-medium", help="config preset of both methods (default cpu-medium)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--set", dest="sets", nargs="+", action="extend", default=[], metavar="KEY=VALUE",
                    help="config overrides for GaussianDS only (e.g. a candidate fix)")
    ap.add_argument("--both", nargs="+", action="extend", default=[], metavar="KEY=VALUE",
                    help="config overrides for both methods")
    ap.add_argument("--work", default=None, help="folder for the scene, runs and logs (reused between calls)")
    ap.add_argument("--json", default=None, help="also write the per-seed metrics to this JSON file")
    a = ap.parse_args(argv)
    work = Path(a.work or tempfile.mkdtemp(prefix="gsbench-psnr-cost-")).resolve()
    work.mkdir(parents=True, exist_ok=True)
    print(f"semantic_psnr_cost: work folder {work}", file=sys.stderr)
    if a.scene is None:
        scene = work / "tabletop-medium"
        if not (scene / "gsbench_scene.json").exists():
            _run([*GSBENCH, "-q", "make-scene", "--preset", "tabletop-medium", "--out", str(scene), "--no-progress"],
                 work / "make-scene.log")
    else:
        scene = Path(a.scene).resolve()
        if not scene.is_dir():
            raise SystemExit(f"semantic_psnr_cost: --scene {a.scene}: not a folder")
    rows = []
    for seed in a.seeds:
        rows.append({"seed": seed,
                     "vanilla": train_and_eval("vanilla", scene, a.preset, seed, list(a.both), work),
                     "gaussiands": train_and_eval("gaussiands", scene, a.preset, seed, [*a.both, *a.sets], work)})
    label = " ".join(a.sets) or "defaults"
    print(f"scene {scene.name}, preset {a.preset}")
    print(table(rows, label))
    if a.json:
        tmp = Path(a.json).with_suffix(".tmp")
        tmp.write_text(json.dumps({"scene": str(scene), "preset": a.preset, "gaussiands_set": a.sets,
                                   "both_set": a.both, "rows": rows}, indent=1) + "\n")
        tmp.replace(a.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
