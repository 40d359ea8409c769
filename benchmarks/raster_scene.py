"""Benchmark: the cpu rasterizer on the Gaussians a training step renders, saved once and timed by
any version of gsbench (benchmarks/versus.py times both of its sides on the same file).

    .venv/bin/python benchmarks/raster_scene.py --make field.pt [--size 20000@256x192]
    .venv/bin/python benchmarks/raster_scene.py --time field.pt [--repeats 7]

--make: the field `benchmarks/train_speed.py` trains from (a generated tabletop-small scene at WxH,
N randomly initialised Gaussians, 3 feature channels) and its first three views' cameras, saved as
plain tensors and arrays.
--time: forward (`render()` under no_grad) and forward+backward (every parameter requiring grad, a
fixed random linear loss on every output) ms of `render(backend="cpu")` on each saved camera, the
best of --repeats per camera, averaged over the cameras; the step is render_cpu.py's (this folder's
copy). It uses only `GaussianField`, `Camera` and `render`, so older commits can be timed on the
same inputs. render_cpu.py's random scene has
Gaussians a pixel or two wide; these are the sizes training starts from (docs/benchmarks.md says why
the speed-up differs between the two).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
# isort: off
# render_cpu imports gsbench before torch (gsbench's OpenMP default, as in the other benchmarks);
# its training-like step (every parameter requiring grad, a fixed random loss) is the one timed here
import render_cpu  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from gsbench.camera import Camera  # noqa: E402
from gsbench.gaussians import GaussianField  # noqa: E402
from gsbench.render import render  # noqa: E402
# isort: on

CAMERAS = 3


def make(out: Path, size: str) -> None:
    """Save train_speed's initial field at `size` (N@WxH) and its first cameras to `out`."""
    import train_speed as TS

    from gsbench.datasets import load_scene
    from gsbench.train.initial_field import scene_init
    n, wh = size.split("@")
    w, h = (int(v) for v in wh.split("x"))
    root = Path(tempfile.mkdtemp(prefix="gsbench-raster-scene-"))
    cfg = TS._config("gaussiands", int(n), w, torch.device("cpu"), 10, 10, root)
    scene = load_scene(TS._scene(root, w, h))
    field, _ = scene_init(scene, cfg, 3)
    cams = [scene.cameras[i] for i in range(min(CAMERAS, len(scene.cameras)))]
    torch.save({"field": {k: v for k, v in field.tensors().items() if v is not None},
                "cameras": [(np.asarray(c.K), np.asarray(c.world_to_camera), c.width, c.height) for c in cams],
                "size": size}, out)
    print(f"wrote {out}: {n} Gaussians, {len(cams)} cameras at {w}x{h}")


def _step(field: GaussianField, cam: Camera) -> None:
    render_cpu._step(field, cam, "cpu")


def _forward(field: GaussianField, cam: Camera) -> None:
    with torch.no_grad():
        render(field, cam, backend="cpu")


def time_file(path: Path, repeats: int) -> dict:
    """{"fwd_ms", "fwdbwd_ms", "threads", "size"} of the saved field."""
    d = torch.load(path, weights_only=False)
    field = GaussianField(**d["field"])
    cams = [Camera(np.asarray(K), np.asarray(w2c), int(w), int(h)) for K, w2c, w, h in d["cameras"]]
    for c in cams:                      # compile / load the kernels, warm the allocator
        _step(field, c)
    res = {"threads": torch.get_num_threads(), "size": d["size"]}
    for name, fn in (("fwd_ms", _forward), ("fwdbwd_ms", _step)):
        best = []
        for c in cams:
            ts = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                fn(field, c)
                ts.append(time.perf_counter() - t0)
            best.append(min(ts))
        res[name] = 1e3 * sum(best) / len(best)
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--make", type=Path, help="write the field and cameras to this file")
    ap.add_argument("--time", type=Path, help="time the cpu rasterizer on this file")
    ap.add_argument("--size", default="20000@256x192", help="N@WxH (with --make)")
    ap.add_argument("--repeats", type=int, default=7)
    a = ap.parse_args(argv)
    if (a.make is None) == (a.time is None):
        ap.error("give one of --make FILE or --time FILE")
    if a.make is not None:
        make(a.make, a.size)
    else:
        print(json.dumps(time_file(a.time, a.repeats)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
