"""Benchmark: does a preset converge on a scene? The preset against the same preset run N times longer.

    .venv/bin/python benchmarks/preset_convergence.py --scene DIR [--presets cpu-small cpu-medium cpu-real]
                                                     [--method vanilla] [--factor 4] [--work DIR]
                                                     [--set KEY=VALUE ...] [--json out.json]
                                                     [--plot out.png]

For each preset it trains `--method` on the scene twice, each in its own `gsbench train` process, then
evaluates with `gsbench eval`: once as the preset says, once with every step count of its schedule
multiplied by `--factor` (iterations, the position LR's decay length, densification start, end and
interval, the opacity reset interval, the SH band interval, and the evaluation, checkpoint and log
intervals so that they happen as often per run). It prints one row per run: held-out PSNR and SSIM,
the number of Gaussians, the training wall time (`train_s`, optimisation only) and the wall time of
the whole `gsbench train` process, and for the long run the PSNR gap to the preset. "Converged"
(docs/real-captures.md) means a gap of at most 0.5 dB. Run it on an otherwise idle
machine: the times are wall times. `--plot` draws held-out PSNR against training time, each preset
joined to its long run, solid where the gap is within the rule and dashed where it is not.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from gsbench.config import load_config, setting

#: the largest gap (dB) to the long run that counts as converged (docs/real-captures.md)
CONVERGED_DB = 0.5

#: the step counts of a schedule, scaled together by --factor
SCHEDULE_KEYS = ("train.iterations", "train.lr.position_max_steps", "train.densify.from_iter",
                 "train.densify.until_iter", "train.densify.interval", "train.densify.opacity_reset_interval",
                 "train.sh_increase_every", "train.eval_every", "train.checkpoint_every", "train.log_every")


def scaled_schedule(method: str, preset: str, factor: int, sets: list[str]) -> list[str]:
    """`--set` overrides that run `preset` `factor` times longer (every step count times factor)."""
    cfg = load_config(method, preset, sets)
    return [f"{k}={int(setting(cfg, k)) * factor}" for k in SCHEDULE_KEYS if setting(cfg, k) is not None]


def train_and_eval(scene: Path, method: str, preset: str, sets: list[str], run: Path) -> dict:
    """One `gsbench train` and `gsbench eval` (skipped when the run folder has results.json)."""
    exe = str(Path(sys.executable).parent / "gsbench")
    wall = None
    if not (run / "results.json").exists():
        t0 = time.perf_counter()
        cmd = [exe, "-q", "train", "--method", method, "--scene", str(scene), "--preset", preset, "--out", str(run),
               "--no-progress"]
        if sets:
            cmd += ["--set", *sets]
        subprocess.run(cmd, check=True)
        wall = time.perf_counter() - t0
        subprocess.run([exe, "-q", "eval", str(run), "--no-progress"], check=True)
    res = json.loads((run / "results.json").read_text())
    summary = json.loads((run / "train_summary.json").read_text())
    m = res["metrics"]
    return {"preset": preset, "sets": sets, "psnr": m.get("psnr"), "ssim": m.get("ssim"),
            "miou_3dovs_heldout": m.get("miou_3dovs_heldout"), "gaussians": summary.get("n_gaussians"),
            "train_s": summary.get("train_s"), "process_s": wall, "iterations": summary.get("iterations"),
            "run": str(run)}


def plot_rows(rows: list[dict], factor: int, title: str, path: Path) -> list[str]:
    """Held-out PSNR against training time: each preset's run joined to its `factor`-times run (rows
    in pairs, as main makes them); returns the legend labels, one per preset."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 4.6))
    labels = []
    for i, (base, long) in enumerate(zip(rows[0::2], rows[1::2])):
        gap = long["psnr"] - base["psnr"]
        converged, color = gap <= CONVERGED_DB, plt.cm.tab10(i % 10)
        label = (f"{Path(base['preset']).stem}: {base['iterations']} steps, gap {gap:+.2f} dB "
                 f"({'converged' if converged else 'not converged'})")
        ax.plot([base["train_s"], long["train_s"]], [base["psnr"], long["psnr"]],
                "-" if converged else "--", color=color, lw=1.6, label=label)
        for run, marker in ((base, "o"), (long, "s")):
            ax.plot(run["train_s"], run["psnr"], marker, color=color, ms=7, mec="black", mew=0.6)
        labels.append(label)
    ax.set_xscale("log")
    ax.set_xlabel("training wall time (s, log scale)")
    ax.set_ylabel("held-out PSNR (dB)")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best",
              title=f"o preset, \u25a1 {factor}x longer; solid: gap \u2264 {CONVERGED_DB} dB", title_fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return labels


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", required=True)
    ap.add_argument("--presets", nargs="+", default=["cpu-small", "cpu-medium", "cpu-real"])
    ap.add_argument("--method", default="vanilla")
    ap.add_argument("--factor", type=int, default=4)
    ap.add_argument("--work", default="preset_convergence_runs", help="run folders (reused when finished)")
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE", help="overrides for every run")
    ap.add_argument("--json", default=None)
    ap.add_argument("--plot", default=None, help="PNG: held-out PSNR against training time")
    args = ap.parse_args(argv)
    if args.factor < 2:
        raise SystemExit("preset_convergence: --factor must be at least 2")
    scene, work = Path(args.scene), Path(args.work)
    rows = []
    print("| scene | method | preset | steps | PSNR | SSIM | Gaussians | train s | process s | "
          f"gap to {args.factor}x |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for preset in args.presets:
        name = Path(preset).stem
        base = train_and_eval(scene, args.method, preset, args.set, work / f"{args.method}_{name}")
        long = train_and_eval(scene, args.method, preset,
                              [*args.set, *scaled_schedule(args.method, preset, args.factor, args.set)],
                              work / f"{args.method}_{name}_x{args.factor}")
        long["gap_db"] = long["psnr"] - base["psnr"]
        for r, label in ((base, name), (long, f"{name} x{args.factor}")):
            gap = f"{r['gap_db']:+.2f}" if "gap_db" in r else ""
            proc = f"{r['process_s']:.0f}" if r["process_s"] is not None else "(reused)"
            print(f"| {scene.name} | {args.method} | {label} | {r['iterations']} | {r['psnr']:.2f} | {r['ssim']:.4f} | "
                  f"{r['gaussians']} | {r['train_s']:.0f} | {proc} | {gap} |", flush=True)
        rows += [base, long]
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    if args.plot:
        plot_rows(rows, args.factor, f"{scene.name}, {args.method}: each preset and the same {args.factor}x longer",
                  Path(args.plot))
    return 0


if __name__ == "__main__":
    sys.exit(main())
