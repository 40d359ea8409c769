"""Benchmark: training iterations per second of the harness (vanilla, gaussiands) against a bare step.

    .venv/bin/python benchmarks/train_speed.py [--sizes 3000@128x96,10000@256x192] [--iters 60]
                                               [--devices cpu,cuda] [--json out.json]

For each device (cpu always; cuda where available) and each size N@WxH it prints one Markdown row per
method, all in the same process:
- reference: a bare training step written directly against the renderer: render RGB + 3 feature
  channels + depth of N random Gaussians, L1 against fixed targets, backward, Adam step. On CUDA it
  calls gsplat.rasterization itself; on the CPU it calls gsbench.render with the `cpu` backend (the
  backend the harness uses there);
- vanilla, gaussiands: `gsbench.runs.train_run` on a generated tabletop-small scene at WxH with
  densification off and N randomly initialised Gaussians (train.init.num_random), so N stays fixed.
  it/s comes from train_log.jsonl (`wall_s`, the trainer's own step timer, synchronised at log steps),
  over the steps after the first log interval (warm-up: numba compile, caches, CUDA kernels).
  Priors, autoencoder and evaluation are outside the timed steps.
Each harness row is also printed as a ratio to the reference row of the same device and size
(ratio = harness it/s / reference it/s) and gaussiands as a ratio to vanilla. Ratios are taken within
one process on one machine; absolute it/s depend on the machine and its load.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import gsbench  # noqa: F401  (before torch: gsbench's OpenMP default)
import torch

from gsbench.gaussians import GaussianField
from gsbench.render import render
from gsbench.scene import Camera


def _random_field(n: int, device: torch.device, feats: int = 3, seed: int = 0) -> GaussianField:
    g = torch.Generator().manual_seed(seed)
    means = torch.rand(n, 3, generator=g) * torch.tensor([2.0, 1.5, 1.0]) - torch.tensor([1.0, 0.75, -2.0])
    f = GaussianField(means, torch.full((n, 3), -3.5), torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
                      torch.zeros(n), torch.rand(n, 3, generator=g), torch.rand(n, feats, generator=g))
    return f.to(device=device)


def _camera(w: int, h: int) -> Camera:
    import numpy as np
    f = 0.9 * w
    return Camera(np.array([[f, 0, w / 2], [0, f, h / 2], [0, 0, 1.0]]), np.eye(4), w, h)


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def reference_its(n: int, w: int, h: int, device: torch.device, iters: int) -> tuple[float, str]:
    """it/s of a bare step (render RGB + 3 features + depth, L1, backward, Adam)."""
    fld = _random_field(n, device)
    params = {k: torch.nn.Parameter(v.clone()) for k, v in fld.tensors().items() if v is not None}
    opt = torch.optim.Adam(params.values(), lr=1e-3, eps=1e-15)
    cam = _camera(w, h)
    target = torch.rand(h, w, 7, device=device)
    if device.type == "cuda":
        import gsplat
        from gsbench.render.gsplat_backend import gsplat_arguments
        label = "bare gsplat step"

        def step() -> None:
            f = GaussianField(**params)
            kw = gsplat_arguments(f, cam)
            img, alpha, _ = gsplat.rasterization(**kw)
            loss = (img[0] - target).abs().mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
    else:
        label = "bare cpu-backend step"

        def step() -> None:
            out = render(GaussianField(**params), cam, backend="cpu")
            pred = torch.cat([out.rgb, out.features, out.depth[..., None]], -1)
            loss = (pred - target).abs().mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
    for _ in range(max(3, iters // 10)):
        step()
    _sync(device)
    t0 = time.perf_counter()
    for _ in range(iters):
        step()
    _sync(device)
    return iters / (time.perf_counter() - t0), label


def harness_its(method: str, n: int, w: int, h: int, device: torch.device, iters: int, root: Path) -> float:
    from gsbench.config import load_config
    from gsbench.datasets.synthetic import make_scene
    from gsbench.runs import train_run
    from gsbench.store import read_jsonl
    scene = root / f"scene_{w}x{h}"
    if not scene.exists():
        make_scene("tabletop-small", scene, seed=0, views=10, resolution=(w, h))
    log_every = max(5, iters // 4)
    cfg = load_config(method, "cpu-small", [
        f"train.device={device}", "backend=auto", f"train.iterations={iters + log_every}", f"train.max_width={w}",
        "train.densify.enabled=false", "train.init.mode=random", f"train.init.num_random={n}",
        "train.eval_every=0", "train.checkpoint_every=0", f"train.log_every={log_every}",
        "gaussiands.autoencoder.epochs=20", f"priors.cache_dir={root / 'cache'}"])
    run = train_run(cfg, scene, root / f"{method}_{device.type}_{n}_{w}x{h}", progress=False)
    log = [r for r in read_jsonl(run / "train_log.jsonl") if "loss" in r]
    first, last = log[0], log[-1]
    return (last["step"] - first["step"]) / max(1e-9, last["wall_s"] - first["wall_s"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="3000@128x96,10000@256x192", help="N@WxH,... (Gaussians @ resolution)")
    ap.add_argument("--iters", type=int, default=60, help="timed steps per row (after warm-up)")
    ap.add_argument("--devices", default="cpu,cuda", help="cpu and/or cuda (cuda rows only where available)")
    ap.add_argument("--json", default=None, help="also write the rows to this JSON file")
    a = ap.parse_args(argv)
    sizes = []
    for s in a.sizes.split(","):
        try:
            n, res = s.split("@")
            w, h = res.lower().split("x")
            sizes.append((int(n), int(w), int(h)))
        except ValueError:
            ap.error(f"--sizes: {s!r} is not N@WxH")
    devices = []
    for d in a.devices.split(","):
        if d == "cuda" and not torch.cuda.is_available():
            print("cuda: not available on this machine, no cuda rows", file=sys.stderr)
            continue
        devices.append(torch.device("cuda", 0) if d == "cuda" else torch.device(d))
    rows = []
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, {a.iters} timed steps per row")
    print("| device | N | WxH | row | it/s | ratio to reference | ratio to vanilla |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for dev in devices:
            for n, w, h in sizes:
                ref, label = reference_its(n, w, h, dev, a.iters)
                r = {"device": str(dev), "n": n, "width": w, "height": h}
                rows.append(dict(r, row=label, its=ref))
                print(f"| {dev} | {n} | {w}x{h} | {label} | {ref:.1f} | 1.00 | |", flush=True)
                van = None
                for method in ("vanilla", "gaussiands"):
                    its = harness_its(method, n, w, h, dev, a.iters, root)
                    van = its if method == "vanilla" else van
                    rel = f"{its / van:.2f}" if method == "gaussiands" and van else ""
                    rows.append(dict(r, row=method, its=its, ratio_reference=its / ref,
                                     ratio_vanilla=(its / van) if method == "gaussiands" else None))
                    print(f"| {dev} | {n} | {w}x{h} | {method} | {its:.1f} | {its / ref:.2f} | {rel} |", flush=True)
    if a.json:
        from gsbench.store import write_json_atomic
        write_json_atomic(Path(a.json), {"rows": rows, "iters": a.iters, "torch": torch.__version__})
    return 0


if __name__ == "__main__":
    sys.exit(main())
