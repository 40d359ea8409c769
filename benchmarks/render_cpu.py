"""Benchmark: the `cpu` render backend against the `torch` reference on the same scenes.

    .venv/bin/python benchmarks/render_cpu.py [--scenes 64x64/1000,128x128/10000,256x256/50000]
                                              [--features 3] [--repeats 5] [--threads N] [--json out.json]

For each scene (random Gaussians in front of a pinhole camera; rgb + depth + `--features` feature
channels) it prints one Markdown table row per scene:
- forward ms: best wall time over the repeats of `render()` under torch.no_grad() (evaluation);
- fwd+bwd ms: best wall time of `render()` with every parameter requiring grad plus
  `loss.backward()` of a fixed random linear loss on rgb, depth, features and alpha (training);
  best-of-N because the machine may be shared (the least disturbed run); medians go to --json;
- peak MiB: peak resident-memory increase during one forward+backward, measured in a fresh
  subprocess per (backend, scene): after imports, scene set-up and a warm-up render of a tiny
  scene (numba compile/cache load, thread pools), the kernel's peak-RSS counter is reset
  (/proc/self/clear_refs = 5), then VmHWM - VmRSS(before) is read after the step. RSS sees every
  allocation (torch, numpy and numba's), unlike tracemalloc;
- max |diff|: max absolute difference of all outputs (rgb, depth, features, alpha) between the
  two backends, and grad rel: max over parameters of max|g_cpu - g_torch| / max|g_torch|;
- speed-up: torch time / cpu time; mem ratio: torch peak / cpu peak.
Both backends use the same number of threads (torch.get_num_threads(), or --threads).
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

import numpy as np

import gsbench  # noqa: F401  (before torch: gsbench's OpenMP default, the same for both backends)

# isort: split
import torch

from gsbench.camera import Camera
from gsbench.gaussians import GaussianField
from gsbench.render import render

DEFAULT_SCENES = "64x64/1000,128x128/10000,256x256/50000"


def make_scene(width: int, height: int, n: int, n_features: int, seed: int = 0) -> tuple[GaussianField, Camera]:
    """Random Gaussians filling the view frustum between z = 2 and 6, a few pixels wide each."""
    g = torch.Generator().manual_seed(seed)
    f = float(width)
    z = torch.rand(n, generator=g) * 4.0 + 2.0
    x = (torch.rand(n, generator=g) - 0.5) * 1.1 * z * width / f
    y = (torch.rand(n, generator=g) - 0.5) * 1.1 * z * height / f
    means = torch.stack([x, y, z], 1)
    # world scale 0.01..0.06 -> screen sigma of roughly 0.3..4 px at 128 px width
    log_scales = torch.log(torch.rand(n, 3, generator=g) * 0.05 + 0.01) + float(np.log(128.0 / width))
    quats = torch.randn(n, 4, generator=g)
    opacity_logits = torch.randn(n, generator=g) * 2.0
    colors = torch.rand(n, 3, generator=g)
    feats = torch.randn(n, n_features, generator=g) if n_features > 0 else None
    K = np.array([[f, 0.0, width / 2.0], [0.0, f, height / 2.0], [0.0, 0.0, 1.0]])
    return GaussianField(means, log_scales, quats, opacity_logits, colors, feats), Camera(K, np.eye(4), width, height)


def _leaf_field(field: GaussianField, grad: bool) -> GaussianField:
    return GaussianField(**{k: (None if v is None else v.detach().clone().requires_grad_(grad))
                            for k, v in field.tensors().items()})


def _loss_weights(out) -> list[torch.Tensor]:
    g = torch.Generator().manual_seed(1)
    ws = [torch.randn(out.rgb.shape, generator=g), torch.randn(out.depth.shape, generator=g),
          torch.randn(out.alpha.shape, generator=g)]
    if out.features is not None:
        ws.append(torch.randn(out.features.shape, generator=g))
    return ws


def _step(field: GaussianField, camera: Camera, backend: str):
    """One training-like forward+backward; returns (output, {param: grad})."""
    leaf = _leaf_field(field, True)
    out = render(leaf, camera, backend=backend)
    ws = _loss_weights(out)
    loss = (out.rgb * ws[0]).sum() + (out.depth * ws[1]).sum() + (out.alpha * ws[2]).sum()
    if out.features is not None:
        loss = loss + (out.features * ws[3]).sum()
    loss.backward()
    return out, {k: v.grad for k, v in leaf.tensors().items() if v is not None}


def _time(fn, repeats: int) -> tuple[float, float]:
    """(best, median) wall time in ms over `repeats` calls."""
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return 1000.0 * min(ts), 1000.0 * statistics.median(ts)


def _status() -> dict[str, int]:
    d = {}
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(("VmRSS:", "VmHWM:")):
                k, v = line.split(":")
                d[k] = int(v.split()[0])  # kB
    return d


def measure_memory(backend: str, width: int, height: int, n: int, n_features: int, seed: int) -> float:
    """Peak RSS increase (MiB) of one forward+backward (run in a fresh process)."""
    field, camera = make_scene(width, height, n, n_features, seed)
    tiny, tiny_cam = make_scene(16, 16, 4, n_features, seed)
    _step(tiny, tiny_cam, backend)      # compile / load caches, start thread pools
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    before = _status()["VmRSS"]
    _step(field, camera, backend)
    return (_status()["VmHWM"] - before) / 1024.0


def _memory_subprocess(backend: str, width: int, height: int, n: int, n_features: int, seed: int,
                       threads: int) -> float:
    cmd = [sys.executable, os.path.abspath(__file__), "--_memory", backend, str(width), str(height), str(n),
           "--features", str(n_features), "--seed", str(seed), "--threads", str(threads)]
    res = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return float(res.stdout.strip().splitlines()[-1])


def bench_scene(width: int, height: int, n: int, n_features: int, seed: int, repeats: int, threads: int) -> dict:
    field, camera = make_scene(width, height, n, n_features, seed)
    row = {"size": f"{width}x{height}", "gaussians": n, "channels": 4 + n_features}
    outs, grads = {}, {}
    for backend in ("torch", "cpu"):
        reps = repeats if backend == "cpu" else max(1, min(repeats, 3))
        outs[backend], grads[backend] = _step(field, camera, backend)   # warm-up + result
        with torch.no_grad():
            row[f"fwd_ms_{backend}"], row[f"fwd_ms_median_{backend}"] = _time(
                lambda b=backend: render(field, camera, backend=b), reps)
        row[f"fwdbwd_ms_{backend}"], row[f"fwdbwd_ms_median_{backend}"] = _time(
            lambda b=backend: _step(field, camera, b), reps)
        row[f"peak_mib_{backend}"] = _memory_subprocess(backend, width, height, n, n_features, seed, threads)
        print(f"  {backend}: done", file=sys.stderr, flush=True)
    o_c, o_t = outs["cpu"], outs["torch"]
    diffs = [(o_c.rgb - o_t.rgb).abs().max(), (o_c.depth - o_t.depth).abs().max(), (o_c.alpha - o_t.alpha).abs().max()]
    if o_t.features is not None:
        diffs.append((o_c.features - o_t.features).abs().max())
    row["max_abs_diff"] = float(max(d.detach() for d in diffs))
    row["grad_rel_diff"] = float(max(((grads["cpu"][k] - g).abs().max() / g.abs().max().clamp(min=1e-30)).item()
                                     for k, g in grads["torch"].items()))
    row["n_visible"] = o_t.info.get("n_visible")
    row["speedup_fwd"] = row["fwd_ms_torch"] / row["fwd_ms_cpu"]
    row["speedup_fwdbwd"] = row["fwdbwd_ms_torch"] / row["fwdbwd_ms_cpu"]
    row["mem_ratio"] = row["peak_mib_torch"] / max(row["peak_mib_cpu"], 1e-9)
    return row


def markdown(rows: list[dict]) -> str:
    head = ("| size | Gaussians | channels | forward ms torch / cpu | fwd+bwd ms torch / cpu | peak MiB torch / cpu "
            "| max abs diff | grad rel diff | speed-up fwd / fwd+bwd | memory ratio |")
    lines = [head, "|" + "---|" * 10]
    for r in rows:
        lines.append(
            f"| {r['size']} | {r['gaussians']} | {r['channels']} "
            f"| {r['fwd_ms_torch']:.1f} / {r['fwd_ms_cpu']:.1f} "
            f"| {r['fwdbwd_ms_torch']:.1f} / {r['fwdbwd_ms_cpu']:.1f} "
            f"| {r['peak_mib_torch']:.1f} / {r['peak_mib_cpu']:.1f} "
            f"| {r['max_abs_diff']:.2e} | {r['grad_rel_diff']:.2e} "
            f"| {r['speedup_fwd']:.1f}x / {r['speedup_fwdbwd']:.1f}x | {r['mem_ratio']:.1f}x |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenes", default=DEFAULT_SCENES, help="comma list of WxH/N (default: %(default)s)")
    p.add_argument("--features", type=int, default=3, help="feature channels besides rgb and depth (default 3)")
    p.add_argument("--repeats", type=int, default=5, help="timed repeats (best and median; torch uses at most 3)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=0, help="torch/numba threads (default: torch's default)")
    p.add_argument("--json", default=None, help="also write the rows to this JSON file")
    p.add_argument("--_memory", nargs=4, metavar=("BACKEND", "W", "H", "N"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.threads > 0:
        torch.set_num_threads(a.threads)
    threads = torch.get_num_threads()
    if a._memory:
        b, w, h, n = a._memory
        print(measure_memory(b, int(w), int(h), int(n), a.features, a.seed))
        return 0
    rows = []
    for spec in a.scenes.split(","):
        size, n = spec.split("/")
        w, h = (int(v) for v in size.lower().split("x"))
        print(f"scene {w}x{h}, {n} Gaussians, {4 + a.features} channels, {threads} threads",
              file=sys.stderr, flush=True)
        rows.append(bench_scene(w, h, int(n), a.features, a.seed, a.repeats, threads))
    print(markdown(rows))
    print(f"\nthreads: {threads}; GOMP_SPINCOUNT={os.environ.get('GOMP_SPINCOUNT')}; torch {torch.__version__}; "
          f"timing: best of repeats; memory: peak RSS increase of one forward+backward in a fresh process")
    if a.json:
        from gsbench.store import write_json_atomic
        write_json_atomic(a.json, {"rows": rows, "threads": threads, "torch": torch.__version__})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
