"""Benchmark: the share of pixels in GaussianDS's depth-edge map E_d with the weight-free `gt` depth prior.

    .venv/bin/python benchmarks/edge_share.py [--work DIR] [--presets tabletop-medium room-medium]
                                             [--sizes 256x192 1008x756] [--distortions 0 1 2] [--views 4]
                                             [--prior-module path/to/depth.py] [--set KEY=VALUE ...]

For each preset and size it makes a synthetic scene with `gsbench make-scene` (kept in --work and
reused), then, for each `priors.depth.distortion`, builds the depth prior and E_d the way training
does: the default config with that distortion, the views and training size of
`build_priors_request`, the provider's `compute_depth` (what `prepare_priors` calls on a cache
miss), then `depth_edges` with `gaussiands.edges` and `edge_coverage`. It prints one table row per
scene and size: the mean share of E_d pixels over the views (%) and, in brackets, how many views
fall under `EDGE_FLOOR` (where training warns). The last column is the same E_d on the exact GT
disparity (1 / z, no blur, no distortion): the most any prior can give at that size, since Canny
draws one-pixel lines whatever the edge's width. `--prior-module` loads another version of
gsbench/priors/depth.py from a file (e.g. a copy taken before a change) and uses its
`compute_depth`, to set the two side by side. What the numbers mean: docs/priors.md.
"""
from __future__ import annotations

import argparse
import importlib.util
import sys
import tempfile
from pathlib import Path
from types import ModuleType

import numpy as np

import gsbench  # noqa: F401  (before torch: gsbench's OpenMP default)
from gsbench.cli import main as gsbench_main
from gsbench.config import load_config
from gsbench.datasets import load_scene
from gsbench.methods.registry import build_priors_request
from gsbench.priors import depth as current_depth
from gsbench.resize import resize_nearest
from gsbench.train.losses import EDGE_FLOOR, depth_edges, edge_coverage


def parse_size(text: str) -> tuple[int, int]:
    """'WxH' -> (W, H)."""
    w, _, h = text.lower().partition("x")
    return int(w), int(h)


def load_prior_module(path: str | None) -> ModuleType:
    """gsbench.priors.depth, or the depth.py at `path` loaded as a separate module."""
    if not path:
        return current_depth
    spec = importlib.util.spec_from_file_location("edge_share_depth_alt", path)
    if spec is None or spec.loader is None:
        raise SystemExit(f"edge_share: cannot load {path} as a module")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod     # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


def scene_folder(work: Path, preset: str, size: tuple[int, int], views: int, seed: int) -> Path:
    """The scene (made once with `gsbench make-scene`, then reused)."""
    out = work / f"{preset}_{size[0]}x{size[1]}_v{views}_s{seed}"
    if not (out / "gsbench_scene.json").exists():
        rc = gsbench_main(["make-scene", "--preset", preset, "--out", str(out), "--seed", str(seed),
                           "--views", str(views), "--resolution", f"{size[0]}x{size[1]}", "--no-progress", "-q"])
        if rc != 0:
            raise SystemExit(f"edge_share: make-scene {preset} {size} failed (exit {rc})")
    return out


def edge_maps(cfg: dict, depth: dict) -> dict:
    """E_d of each view's (values, valid), with the config's `gaussiands.edges`."""
    e = cfg["gaussiands"]["edges"]
    return {v: depth_edges(vals, ok, e["canny_low"], e["canny_high"], int(e["dilate"]), e.get("size"))
            for v, (vals, ok) in depth.items()}


def edge_share(scene, prior: ModuleType, distortion: float, sets: list[str]) -> tuple[float, int, int]:
    """(mean E_d share over the training views, views under EDGE_FLOOR, views) at one distortion."""
    cfg = load_config("gaussiands", None, [f"priors.depth.distortion={distortion:g}", *sets])
    req = build_priors_request(cfg, scene)
    depth = prior.compute_depth(scene, req["priors"]["depth"], req["view_ids"], tuple(req["size"]),
                                seed=req["seed"], progress=False)
    share, n_empty = edge_coverage(edge_maps(cfg, {v: (p.values, p.valid) for v, p in depth.items()}), EDGE_FLOOR)
    return share, n_empty, len(depth)


def gt_edge_share(scene, sets: list[str]) -> tuple[float, int, int]:
    """`edge_share` on the exact GT disparity at the training size (the upper bound)."""
    cfg = load_config("gaussiands", None, sets)
    req = build_priors_request(cfg, scene)
    depth = {}
    for v in req["view_ids"]:
        z = resize_nearest(np.asarray(scene.gt_depth(v), dtype=np.float64), *req["size"])
        ok = np.isfinite(z) & (z > 1e-6)
        depth[v] = (np.where(ok, 1.0 / np.where(ok, z, 1.0), 0.0), ok)
    share, n_empty = edge_coverage(edge_maps(cfg, depth), EDGE_FLOOR)
    return share, n_empty, len(depth)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default=None, help="folder for the scenes (default: a temporary one)")
    ap.add_argument("--presets", nargs="+", default=["tabletop-medium", "room-medium"])
    ap.add_argument("--sizes", nargs="+", default=["256x192", "1008x756"])
    ap.add_argument("--distortions", nargs="+", type=float, default=[0.0, 1.0, 2.0])
    ap.add_argument("--views", type=int, default=4)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--prior-module", default=None, help="another depth.py to take compute_depth from")
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE",
                    help="config overrides, e.g. gaussiands.edges.size=518")
    args = ap.parse_args(argv)
    prior = load_prior_module(args.prior_module)
    tmp = None if args.work else tempfile.TemporaryDirectory(prefix="edge_share_")
    work = Path(args.work or tmp.name)
    work.mkdir(parents=True, exist_ok=True)
    sizes = [parse_size(t) for t in args.sizes]
    folders = {(p, sz): scene_folder(work, p, sz, args.views, args.seed) for p in args.presets for sz in sizes}
    print(f"E_d share (% of pixels, mean over views; [views under {100 * EDGE_FLOOR:g} %]), "
          f"prior from {args.prior_module or 'gsbench.priors.depth'}; overrides: {' '.join(args.set) or 'none'}")
    print("| scene | size | " + " | ".join(f"distortion {d:g}" for d in args.distortions) + " | GT disparity |")
    print("|---|---|" + "---:|" * (len(args.distortions) + 1))
    for (preset, size), folder in folders.items():
        scene = load_scene(folder)
        results = [edge_share(scene, prior, d, args.set) for d in args.distortions] + [gt_edge_share(scene, args.set)]
        cells = [f"{100 * share:.2f} [{n_empty}/{n}]" for share, n_empty, n in results]
        print(f"| {preset} | {size[0]}x{size[1]} | " + " | ".join(cells) + " |", flush=True)
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
