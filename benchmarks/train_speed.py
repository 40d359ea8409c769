"""Benchmark: training iterations per second of the harness (vanilla, gaussiands) against a bare step.

    .venv/bin/python benchmarks/train_speed.py [--sizes 3000@128x96,10000@256x192] [--iters 60]
                                               [--devices cpu,cuda] [--json out.json]

For each device (cpu always; cuda where available) and each size N@WxH it prints one Markdown row per
method, all in the same process:
- reference: a bare training step written directly against the renderer: render RGB + 3 feature
  channels + depth of the same N initial Gaussians and views as the harness rows, L1 against the
  image (and zero features/depth), backward, Adam step (on the CPU with PyTorch's ops on one thread,
  as the trainer runs its steps: gsbench.render.threads). On CUDA it
  calls gsplat.rasterization itself; on the CPU it calls gsbench.render with the `cpu` backend (the
  backend the harness uses there);
- vanilla, gaussiands: `gsbench.runs.train_run` on a generated tabletop-small scene at WxH with
  densification off and N randomly initialised Gaussians (train.init.num_random), so N stays fixed.
  it/s comes from train_log.jsonl (`wall_s`, the trainer's own step timer, synchronised at log steps),
  over the steps after the first log interval (warm-up: numba compile, caches, CUDA kernels).
  Priors, autoencoder and evaluation are outside the timed steps.
A second table gives each harness row's step in ms per phase (projection, raster forward, raster
backward, losses, optimiser, densify, other; see `phase_ms`), from the gsbench.step_timers timers over
the whole run. Each harness row is also printed as a ratio to the reference row of the same device and size
(ratio = harness it/s / reference it/s) and gaussiands as a ratio to vanilla. Ratios are taken within
one process on one machine; absolute it/s depend on the machine and its load.
"""
from __future__ import annotations

import argparse
import contextlib
import sys
import tempfile
import time
from pathlib import Path

import gsbench  # noqa: F401  (before torch: gsbench's OpenMP default)

# isort: split
import torch

from gsbench import rundir
from gsbench.gaussians import GaussianField
from gsbench.render import render
from gsbench.render.threads import torch_ops_serial
from gsbench.train.adam import Adam


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def _scene(root: Path, w: int, h: int) -> Path:
    from gsbench.datasets.synthetic import make_scene
    scene = root / f"scene_{w}x{h}"
    if not scene.exists():
        make_scene("tabletop-small", scene, seed=0, views=10, resolution=(w, h))
    return scene


def _config(method: str, n: int, w: int, device: torch.device, iters: int, log_every: int, root: Path) -> dict:
    from gsbench.config import load_config
    return load_config(method, "cpu-small", [
        f"train.device={device}", "backend=auto", f"train.iterations={iters}", f"train.max_width={w}",
        "train.densify.enabled=false", "train.init.mode=random", f"train.init.num_random={n}",
        "train.eval_every=0", "train.checkpoint_every=0", f"train.log_every={log_every}",
        "semantic.autoencoder.epochs=20", f"priors.cache_dir={root / 'cache'}"])


def reference_its(n: int, w: int, h: int, device: torch.device, iters: int, root: Path) -> tuple[float, str]:
    """it/s of a bare step (render RGB + 3 features + depth, L1, backward, Adam) on the same scene,
    views and initial Gaussians as the harness rows, so the rasterisation work is the same."""
    from gsbench.datasets import load_scene
    from gsbench.train.initial_field import scene_init
    from gsbench.train.views import load_views
    cfg = _config("gaussiands", n, w, device, iters, iters, root)
    scene = load_scene(_scene(root, w, h))
    views, _ = load_views(scene, cfg, device=device)
    fld, _ = scene_init(scene, cfg, 3)
    params = {k: torch.nn.Parameter(v.to(device).clone()) for k, v in fld.tensors().items() if v is not None}
    opt = Adam(params.values(), lr=1e-3, eps=1e-15)
    ids = sorted(views.cameras)
    targets = {i: torch.cat([views.images[i], torch.zeros(h, w, 4, device=device)], -1) for i in ids}
    if device.type == "cuda":
        import gsplat

        from gsbench.render.gsplat_backend import gsplat_arguments
        label = "bare gsplat step"

        def pred_of(cam):
            img, _, _ = gsplat.rasterization(**gsplat_arguments(GaussianField(**params), cam))
            return img[0]
    else:
        label = "bare cpu-backend step"

        def pred_of(cam):
            out = render(GaussianField(**params), cam, backend="cpu")
            return torch.cat([out.rgb, out.features, out.depth[..., None]], -1)

    def step(k: int) -> None:
        # on the CPU, PyTorch's ops on one thread and the kernels on all, as the trainer runs a step
        with torch_ops_serial() if device.type == "cpu" else contextlib.nullcontext():
            i = ids[k % len(ids)]
            loss = (pred_of(views.cameras[i]) - targets[i]).abs().mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
    for k in range(max(3, iters // 10)):
        step(k)
    _sync(device)
    t0 = time.perf_counter()
    for k in range(iters):
        step(k)
    _sync(device)
    return iters / (time.perf_counter() - t0), label


PHASES = ("projection", "raster fwd", "raster bwd", "losses", "optimiser", "densify", "other")


def phase_ms(tot: dict, steps: int, step_s: float) -> dict:
    """ms per step of each phase from gsbench.step_timers totals over `steps` steps of `step_s` seconds in all.

    projection = forward + hand-written backward; losses = the loss terms plus the autograd backward
    that is not the renderer's own (SSIM, L1, the loss terms' graph, SH colours); other = the rest of
    the step (the field's assembly, render glue, bookkeeping)."""
    g = lambda k: tot.get(k, 0.0)  # noqa: E731
    ms = {"projection": g("projection") + g("projection_backward"), "raster fwd": g("raster_forward"),
          "raster bwd": g("raster_backward"),
          "losses": g("losses") + g("backward") - g("raster_backward") - g("projection_backward"),
          "optimiser": g("optimiser"), "densify": g("densify")}
    ms["other"] = step_s - sum(ms.values())
    return {k: 1e3 * v / max(1, steps) for k, v in ms.items()}


def harness_its(method: str, n: int, w: int, h: int, device: torch.device, iters: int,
                root: Path) -> tuple[float, dict]:
    """(it/s after the first log interval, ms per step of each phase over the whole run)."""
    from gsbench import step_timers
    from gsbench.runs import train_run
    from gsbench.store import read_jsonl
    log_every = max(5, iters // 4)
    cfg = _config(method, n, w, device, iters + log_every, log_every, root)
    step_timers.reset()
    step_timers.enable()
    try:
        run = train_run(cfg, _scene(root, w, h), root / f"{method}_{device.type}_{n}_{w}x{h}", progress=False)
    finally:
        step_timers.enable(False)
    log = [r for r in read_jsonl(run / rundir.TRAIN_LOG) if "loss" in r]
    first, last = log[0], log[-1]
    its = (last["step"] - first["step"]) / max(1e-9, last["wall_s"] - first["wall_s"])
    return its, phase_ms(step_timers.totals(), last["step"], last["wall_s"])


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
    phase_rows = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for dev in devices:
            for n, w, h in sizes:
                ref, label = reference_its(n, w, h, dev, a.iters, root)
                r = {"device": str(dev), "n": n, "width": w, "height": h}
                rows.append(dict(r, row=label, its=ref))
                print(f"| {dev} | {n} | {w}x{h} | {label} | {ref:.1f} | 1.00 | |", flush=True)
                van = None
                for method in ("vanilla", "gaussiands"):
                    its, ph = harness_its(method, n, w, h, dev, a.iters, root)
                    # host timers around asynchronous CUDA work (and gsplat, which has no phase timers)
                    # would print a split that is not the GPU's: CPU rows only
                    ph = ph if dev.type == "cpu" else None
                    van = its if method == "vanilla" else van
                    rel = f"{its / van:.2f}" if method == "gaussiands" and van else ""
                    rows.append(dict(r, row=method, its=its, ratio_reference=its / ref,
                                     ratio_vanilla=(its / van) if method == "gaussiands" else None, phases_ms=ph))
                    if ph is not None:
                        phase_rows.append((dev, n, w, h, method, ph))
                    print(f"| {dev} | {n} | {w}x{h} | {method} | {its:.1f} | {its / ref:.2f} | {rel} |", flush=True)
    if phase_rows:
        print("\nms per step by phase (whole run, warm-up included; host wall time; CPU rows only):")
        print("| device | N | WxH | row | " + " | ".join(PHASES) + " | step |")
        print("|---|---|---|---|" + "---|" * (len(PHASES) + 1))
        for dev, n, w, h, method, ph in phase_rows:
            print(f"| {dev} | {n} | {w}x{h} | {method} | " + " | ".join(f"{ph[k]:.1f}" for k in PHASES)
                  + f" | {sum(ph.values()):.1f} |")
    if a.json:
        from gsbench.store import write_json_atomic
        write_json_atomic(Path(a.json), {"rows": rows, "iters": a.iters, "torch": torch.__version__})
    return 0


if __name__ == "__main__":
    sys.exit(main())
