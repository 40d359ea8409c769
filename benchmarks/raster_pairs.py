"""Benchmark: the cpu raster kernels in Gaussian-pixel pairs per second, against the arithmetic limit.

    .venv/bin/python benchmarks/raster_pairs.py --run RUN_DIR [--views 6] [--repeats 7]
                                                [--threads 1,2] [--json out.json]

It renders the first --views training cameras of a trained run (a cpu-medium GaussianDS run of
tabletop-medium is the one docs/benchmarks.md reports) with the `cpu` backend once, captures the
inputs of the two raster passes (`_raster_forward`, `_raster_backward`: depth sort, packing,
binning and the kernels; not the projection), and times each pass alone on them, best of
--repeats per view, for each thread count. d loss / d outputs is a fixed random array.

A pair is a (Gaussian, pixel) pair that contributes to the pixel: the work a rasterizer that
visits only those must do. They are counted by a scalar walk written here that takes the forward
kernel's decisions in its order (exponent, alpha, the skip rules, the transmittance stop); the walk
checks itself against the kernel's last-contributor index and final transmittance of every pixel.
The forward and the backward visit the same pairs.

The limit is docs/benchmarks.md's: about 25 floating-point operations per pair forward (float32
lanes, two 16-wide vector operations per cycle at 3 GHz: 96 GFLOP/s a core) and 60 backward
(float64, two 8-wide operations a cycle: 48 GFLOP/s), so a core does at most 3.84 G forward and
0.8 G backward pairs a second; n threads n times that. Each row prints the measured pairs per
second and the factor by which it stays above that limit (time / time at the limit).
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from functools import partial
from pathlib import Path

import gsbench  # noqa: F401  (before torch: gsbench's OpenMP default)

# isort: split
import numpy as np
import torch
from numba import njit

from gsbench.render import cpu_backend as CB
from gsbench.render import cpu_kernels as K
from gsbench.render.cpu_exp import _expw, _like

FLOPS = {"forward": 25, "backward": 60}                 # per pair (docs/benchmarks.md)
PEAK = {"forward": 96e9, "backward": 48e9}              # FLOP/s of one core (docs/benchmarks.md)


@njit(cache=False)
def count_pairs(gp, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts, width, height, last, t64):
    """(contributing pairs, pixels whose walk disagrees with the kernel's last / final transmittance):
    the forward kernel's per-pixel decisions, one pair at a time."""
    one, mhalf, zero = consts[K.K_ONE], consts[K.K_MHALF], consts[K.K_ZERO]
    amax, amin, tmin = consts[K.K_AMAX], consts[K.K_AMIN], consts[K.K_TMIN]
    pairs = 0
    bad = 0
    for py in range(height):
        for px in range(width):
            t = (py // tile_size) * tiles_x + px // tile_size
            tr = 1.0
            lj = 0
            for j in range(tile_off[t + 1] - tile_off[t]):
                g = ranks[tile_off[t] + j]
                dx = pxc[px] - gp[g, K.MX]
                dy = pyc[py] - gp[g, K.MY]
                power = mhalf * (gp[g, K.CA] * dx * dx + gp[g, K.CC] * dy * dy) - gp[g, K.CB] * dx * dy
                alpha = min(gp[g, K.OP] * _expw(power), amax)
                if not ((power <= zero) & (power >= gp[g, K.THR]) & (alpha >= amin)):
                    continue
                tn = tr * (one - alpha)
                if not (_like(tn, power) > tmin):
                    break
                tr = tn
                lj = j + 1
                pairs += 1
            bad += (lj != last[py, px]) | (tr != t64[py, px])
    return pairs, bad


def capture(run: Path, views: int) -> list[tuple]:
    """The `_raster_forward` arguments of the run's first `views` training cameras."""
    from gsbench.evaluation.frames import frame_sets, train_camera
    from gsbench.evaluation.trained_run import load_run
    method, config, scene = load_run(run)
    fs = frame_sets(scene, config)
    width = config["train"]["max_width"]
    return capture_renders(method.field, [train_camera(scene.cameras[i], width) for i in fs.trained[:views]])


def capture_renders(field, cams: list) -> list[tuple]:
    """The `_raster_forward` arguments of a `cpu` render of `field` at each camera."""
    from gsbench.render import render
    got = []
    real = CB._raster_forward

    def keep(*args, **kw):
        got.append((args, kw))
        return real(*args, **kw)
    CB._raster_forward = keep
    try:
        with torch.no_grad():
            for cam in cams:
                render(field, cam, backend="cpu")
    finally:
        CB._raster_forward = real
    return got


def best(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def measure(captured: list[tuple], threads: int, repeats: int) -> dict:
    """Best-of ms per view of each pass at `threads`, and the pairs of each view."""
    torch.set_num_threads(threads)
    rng = np.random.default_rng(0)
    rows = {"forward": [], "backward": [], "pairs": []}
    for args, kw in captured:
        outs, _, state = CB._raster_forward(*args, **kw)
        g_outs = tuple(rng.standard_normal(o.shape).astype(o.dtype) for o in outs)
        g_t = rng.standard_normal(outs[0].shape[:2]).astype(outs[0].dtype)
        rows["forward"].append(best(partial(CB._raster_forward, *args, **kw), repeats) * 1e3)
        rows["backward"].append(best(partial(CB._raster_backward, state, g_outs, g_t), repeats) * 1e3)
        gp, _, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts, t64, last, _, _ = state
        h, w = t64.shape
        pairs, bad = count_pairs(gp, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts, w, h, last, t64)
        if bad:
            sys.exit(f"raster_pairs: the pair walk disagrees with the kernel on {bad} pixels")
        rows["pairs"].append(pairs)
    return rows


def table(results: dict) -> str:
    lines = ["| threads | pass | pairs / view (M) | ms / view | pairs / s (G) | limit (G/s) | above the limit |",
             "|---|---|---:|---:|---:|---:|---:|"]
    for threads, rows in results.items():
        pairs = statistics.fmean(rows["pairs"])
        for p in ("forward", "backward"):
            ms = statistics.fmean(rows[p])
            rate = pairs / (ms * 1e-3) if ms > 0 else float("nan")
            limit = threads * PEAK[p] / FLOPS[p]
            lines.append(f"| {threads} | {p} | {pairs / 1e6:.2f} | {ms:.2f} | {rate / 1e9:.3f} | {limit / 1e9:.2f} | "
                         f"{limit / rate:.0f}x |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", type=Path, required=True, help="a trained run folder (cpu backend)")
    ap.add_argument("--views", type=int, default=6)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    if not (args.run / "model.pt").exists():
        print(f"{args.run}: not a trained run folder (no model.pt)", file=sys.stderr)
        return 2
    captured = capture(args.run, args.views)
    results = {int(t): measure(captured, int(t), args.repeats) for t in args.threads.split(",")}
    print(table(results))
    if args.json:
        args.json.write_text(json.dumps({"run": str(args.run), "flops_per_pair": FLOPS, "peak_per_core": PEAK,
                                         "results": results}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
