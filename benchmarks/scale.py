"""Scale rehearsal without a GPU: the data path of a LERF-sized scene on the CPU, phase by phase.

    .venv/bin/python benchmarks/scale.py [--views 200] [--size 1440x1080] [--gaussians 300000] [--steps 3]
                                         [--train-width W] [--work DIR] [--scene DIR] [--json out.json]

Phases, each timed and with its own peak resident memory (the kernel's peak-RSS counter is reset
at the start of each phase, gsbench.environment.PeakMemory):
  generate  the synthetic room-medium layout at --views x --size with --gaussians sparse points
            (skipped with --scene, or when --work already holds this scene);
  load      the scene folder and every training image at the training size (gsbench.train.views.load_views);
  priors    depth, masks and features with the weight-free providers of default.yaml, into an empty cache;
  cache     the same request again: every part read back from the cache;
  train     `gsbench train`'s path (gsbench.runs.train_run) for --steps steps: priors from the cache,
            autoencoder, semantic targets, the trainer on --gaussians Gaussians, model.pt;
  eval      one held-out labelled frame: reconstruction metrics and every segmentation protocol.
The default config is the GPU user's (default.yaml: full-size training, SH degree 0) run on the CPU
backend. What the numbers mean and what was fixed for this size: docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import gsbench  # noqa: F401  (before torch: gsbench's OpenMP default)

# isort: split
from gsbench import rundir
from gsbench.environment import PeakMemory

PRESET = "room-medium"


def _current_rss_mb() -> float | None:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return float(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


class Phases:
    """Runs named phases and keeps one row each: wall seconds, peak RSS in the phase, RSS after it."""

    def __init__(self) -> None:
        self.rows: list[dict] = []

    def run(self, name: str, fn, note: str = ""):
        mem = PeakMemory("cpu").start()
        t0 = time.perf_counter()
        out = fn()
        wall = time.perf_counter() - t0
        peak = mem.read()
        self.rows.append({"phase": name, "wall_s": wall, "peak_rss_mb": peak["peak_rss_mb"],
                          "rss_source": peak["rss_source"], "rss_after_mb": _current_rss_mb(), "note": note})
        r = self.rows[-1]
        print(f"[scale] {name}: {wall:.1f} s, peak RSS {r['peak_rss_mb']:.0f} MB", file=sys.stderr, flush=True)
        return out

    def markdown(self) -> str:
        lines = ["| phase | wall s | peak RSS MB | RSS after MB | note |", "|---|---:|---:|---:|---|"]
        for r in self.rows:
            after = "–" if r["rss_after_mb"] is None else f"{r['rss_after_mb']:.0f}"
            lines.append(f"| {r['phase']} | {r['wall_s']:.1f} | {r['peak_rss_mb']:.0f} | {after} | {r['note']} |")
        return "\n".join(lines)


def parse_size(text: str) -> tuple[int, int]:
    from gsbench.datasets.synthetic import parse_resolution
    return parse_resolution(text)


def config_for(args, width: int, cache: Path) -> dict:
    """default.yaml (the GPU user's settings) on the CPU backend, for a few steps on a fixed set of Gaussians."""
    from gsbench.config import load_config
    return load_config("gaussiands", None, [
        "backend=cpu", "train.device=cpu", f"train.iterations={args.steps}", f"train.max_width={width}",
        "train.init.mode=points", f"train.init.max_points={args.gaussians}", "train.eval_every=0",
        "train.eval_views=0", "train.checkpoint_every=0", "train.log_every=1", f"priors.cache_dir={cache}"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--views", type=int, default=200)
    ap.add_argument("--size", type=parse_size, default=(1440, 1080), metavar="WxH")
    ap.add_argument("--gaussians", type=int, default=300_000,
                    help="Gaussians trained (initialised from as many of the generated sparse points)")
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--train-width", type=int, default=None, help="train.max_width (default: the full --size width)")
    ap.add_argument("--work", type=Path, default=None, help="folder for scene, cache and run (default: a temp folder)")
    ap.add_argument("--scene", type=Path, default=None, help="use this generated scene instead of generating one")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.views < 9:
        ap.error("--views must be at least 9 (every 8th view is held out; one held-out view is evaluated)")
    tmp = None
    if args.work is None:
        tmp = Path(tempfile.mkdtemp(prefix="gsbench-scale-"))
    work = args.work or tmp
    work.mkdir(parents=True, exist_ok=True)
    try:
        return _run(args, work)
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


def _run(args, work: Path) -> int:
    import torch

    from gsbench.datasets import load_scene
    from gsbench.datasets.synthetic import make_scene
    from gsbench.evaluation.trained_run import load_run
    from gsbench.methods.base import fit_priors
    from gsbench.runs import train_run
    from gsbench.train.views import load_views
    W, H = args.size
    width = args.train_width or W
    ph = Phases()
    scene_dir = args.scene
    if scene_dir is None:
        scene_dir = work / f"scene_{PRESET}_{args.views}v_{W}x{H}_{args.gaussians}p"
        if (scene_dir / "gsbench_scene.json").exists():
            print(f"[scale] reusing {scene_dir}", file=sys.stderr)
        else:
            ph.run("generate", lambda: make_scene(PRESET, scene_dir, seed=0, views=args.views, resolution=(W, H),
                                                  points=args.gaussians + args.views, progress=False),
                   f"{PRESET}, {args.views} views {W}x{H}, {args.gaussians + args.views} points")
    cache = work / "cache"
    shutil.rmtree(cache, ignore_errors=True)
    cfg = config_for(args, width, cache)
    scene = ph.run("load scene", lambda: load_scene(scene_dir), "scene folder")
    views = ph.run("load images", lambda: load_views(scene, cfg)[0])
    n_train, cam0 = len(views.images), next(iter(views.cameras.values()))
    tw, th = cam0.width, cam0.height
    img_mb = sum(t.numel() * t.element_size() for t in views.images.values()) / 2**20
    ph.rows[-1]["note"] = f"{n_train} training images {tw}x{th}, {img_mb:.0f} MB"
    del views
    run_dir = work / "run"
    shutil.rmtree(run_dir, ignore_errors=True)
    pri = ph.run("priors", lambda: fit_priors(scene, cfg, run_dir, progress=False))
    ph.rows[-1]["note"] = ", ".join(f"{k}={v}" for k, v in pri.providers.items() if v)
    del pri
    pri = ph.run("cache", lambda: fit_priors(scene, cfg, run_dir, progress=False))
    hits = {k: v["hit"] for k, v in pri.cache.items()}
    size_mb = sum(p.stat().st_size for p in cache.rglob("*") if p.is_file()) / 2**20
    ph.rows[-1]["note"] = f"hits {hits}, cache {size_mb:.0f} MB on disk"
    del pri
    ph.run("train", lambda: train_run(cfg, scene_dir, run_dir, progress=False))
    summary = json.loads((run_dir / rundir.TRAIN_SUMMARY).read_text())
    log = [json.loads(x) for x in (run_dir / rundir.TRAIN_LOG).read_text().splitlines() if x.strip()]
    steps = [r["wall_s"] for r in log if "wall_s" in r]
    step_s = (steps[-1] - steps[0]) / (len(steps) - 1) if len(steps) > 1 else (steps[0] if steps else None)
    n_g = summary.get("n_gaussians") or (summary.get("info") or {}).get("n_gaussians")
    ph.rows[-1]["note"] = (f"{args.steps} steps, {n_g} Gaussians, "
                           + (f"{step_s:.1f} s per step after the first" if step_s is not None else "no step time"))
    ph.rows[-1]["note"] = ph.run("eval", lambda: _eval_one(load_run, run_dir))
    print(f"scale rehearsal: {PRESET}, {args.views} views at {W}x{H}, training at {tw}x{th}, "
          f"{n_g} Gaussians, {args.steps} steps, torch {torch.__version__}, {torch.get_num_threads()} threads")
    print(ph.markdown())
    if args.json:
        args.json.write_text(json.dumps({"views": args.views, "size": [W, H], "train_size": [tw, th],
                                         "gaussians": n_g, "steps": args.steps, "phases": ph.rows}, indent=1))
    return 0


def _eval_one(load_run, run_dir: Path) -> str:
    """Reconstruction metrics and every protocol's segmentation of the first held-out labelled view."""
    import torch

    from gsbench.evaluation.frames import frame_sets, train_camera, view_name
    from gsbench.evaluation.image import image_metrics
    from gsbench.evaluation.segmentation import query_mode, resolve_protocols, segmentation
    from gsbench.metric_table import seg_metric
    method, config, scene = load_run(run_dir)
    fs = frame_sets(scene, config)
    i = fs.reconstruction[0]
    cam = train_camera(scene.cameras[i], (config.get("train") or {}).get("max_width"))
    protocols, _ = resolve_protocols(scene, "auto")
    sets = {p: {"held-out": [i]} for p in protocols}
    with torch.no_grad():
        rec = image_metrics(method, scene, [i], [cam], config)
        seg = segmentation(method, scene, protocols, sets, config, modes=(query_mode(config),))
    vals = {k: rec.metrics.get(k) for k in ("psnr", "ssim")}
    vals.update({seg_metric("miou", p, None, "held-out"): seg.metrics.get(seg_metric("miou", p, None, "held-out"))
                 for p in protocols})
    return f"{view_name(scene, i)}: " + ", ".join(
        f"{k} {v:.3f}" if isinstance(v, float) else f"{k} n/a" for k, v in vals.items())


if __name__ == "__main__":
    raise SystemExit(main())
