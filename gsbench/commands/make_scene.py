"""`gsbench make-scene`: render a synthetic scene (analytic ray caster) into the 3D-OVS / LERF-OVS layouts."""
from __future__ import annotations

import argparse
import time

from gsbench.datasets import load_scene
from gsbench.datasets.synthetic import LAYOUT_CHOICES, PRESETS, make_scene, parse_resolution


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--preset", required=True, choices=sorted(PRESETS), help="scene preset")
    parser.add_argument("--out", required=True, help="output folder (must not exist or be empty)")
    parser.add_argument("--seed", type=int, default=0, help="layout / camera seed (default 0)")
    parser.add_argument("--views", type=int, default=None, help="number of views (default: the preset's)")
    parser.add_argument(
        "--resolution", default=None, metavar="WxH", help="image size, e.g. 128x96 (default: the preset's)"
    )
    parser.add_argument(
        "--layout", default="both", choices=LAYOUT_CHOICES, help="label layouts to write (default both)"
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    res = parse_resolution(args.resolution) if args.resolution else None
    t0 = time.perf_counter()
    out = make_scene(args.preset, args.out, seed=args.seed, views=args.views, resolution=res, layout=args.layout,
                     progress=not args.no_progress)
    scene = load_scene(out)
    parts = ", ".join(k for k, v in scene.parts().items() if v)
    cam = scene.cameras[0]
    print(f"wrote {out} ({scene.layout}): {len(scene.cameras)} views {cam.width}x{cam.height}, "
          f"{len(scene.train_ids)} train / {len(scene.test_ids)} test, classes {scene.class_names}, "
          f"parts: {parts} in {time.perf_counter() - t0:.1f} s")
    return 0
