"""`gsbench eval RUN_DIR [--protocol auto|<protocol>|<fork>[,...]]`, or
`gsbench eval --masks PRED_DIR --layout LAYOUT_DIR --protocol lerf|3dovs [--out OUT_DIR]`."""
from __future__ import annotations

import argparse
from pathlib import Path

from gsbench import evaluation as evaluate
from gsbench.errors import InputError
from gsbench.preview_files import PREVIEWS_DIR, read_manifest


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dir", nargs="?", type=Path, help="a trained run folder (writes RUN_DIR/results.json)")
    parser.add_argument("--protocol", default=None, metavar="NAME[,NAME]",
                        help="protocols to score: auto (every protocol the scene supports, each under its default "
                        "fork), protocol names (3dovs, lerf, ...) or fork names (3dovs-threshold, lerf-original, "
                        "...; docs/protocols.md), comma-separated; default: the run's eval.protocol")
    parser.add_argument("--masks", type=Path, help="score a folder of predicted masks instead of a run")
    parser.add_argument("--layout", type=Path, help="with --masks: a LERF-OVS label folder (frame_*.json) "
                        "or a 3D-OVS scene folder (segmentations/)")
    parser.add_argument("--out", type=Path, help="with --masks: where results.json goes (default: the masks folder)")
    parser.add_argument("--boundary-ratio", type=float, default=0.02, help="with --masks: Boundary IoU dilation ratio")
    parser.add_argument("--no-progress", action="store_true")


def _fmt(v) -> str:
    return "null" if v is None else f"{v:.4f}" if isinstance(v, float) else str(v)


def run(args: argparse.Namespace) -> int:
    if args.masks is not None:
        if args.run_dir is not None:
            raise InputError("give either RUN_DIR or --masks, not both")
        if args.layout is None or args.protocol in (None, "auto"):
            raise InputError("--masks needs --layout and --protocol lerf|3dovs")
        res = evaluate.score_mask_folder(args.masks, args.layout, args.protocol, args.out, args.boundary_ratio)
        out = args.out or args.masks
    else:
        if args.run_dir is None:
            raise InputError("give RUN_DIR (a trained run) or --masks PRED_DIR --layout DIR")
        if not args.run_dir.is_dir():
            raise InputError(f"{args.run_dir}: run folder not found")
        res = evaluate.evaluate_run(args.run_dir, protocol=args.protocol, progress=not args.no_progress)
        out = args.run_dir
    for k, v in res["metrics"].items():
        print(f"{k:28s} {_fmt(v)}")
    for k, v in res.get("skipped", {}).items():
        print(f"skipped {k}: {v}")
    for k, names in res.get("frames", {}).items():
        print(f"frames {k} ({res.get('resolution', {}).get(k, '?')}): {len(names)}")
    for k, v in res.get("frames_skipped", {}).items():
        print(f"frame not scored {k}: {v}")
    if res.get("missing", {}).get("count"):
        print(f"missing predictions: {res['missing']['count']} (counted as IoU 0): "
              + ", ".join(res["missing"]["files"][:10]) + (" ..." if res["missing"]["count"] > 10 else ""))
    print(f"wrote {Path(out) / 'results.json'}")
    if args.masks is None:
        m = read_manifest(args.run_dir)
        if m is not None:
            print(f"wrote {Path(out) / PREVIEWS_DIR} ({len(m['frames'])} frames, {len(m['removal'])} removal views "
                  "for the report's pictures)")
    return 0
