"""`gsbench points SCENE`: triangulate sparse points from the known poses of a scene that has none,
and write them as the scene's COLMAP model (sparse/0), which training then uses for initialisation."""
from __future__ import annotations

import argparse
from pathlib import Path

from gsbench.colmap_lib import import_pycolmap
from gsbench.datasets import load_scene
from gsbench.datasets.colmap import find_model_dir
from gsbench.datasets.triangulate import triangulate_scene, write_points
from gsbench.errors import InputError
from gsbench.store import write_json_atomic


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", type=Path, help="scene folder with poses (sparse/0 without points, "
                                                 "poses_bounds.npy or transforms.json) and images/")
    parser.add_argument("--layout", default="auto", help="scene layout (default: detected)")
    parser.add_argument("--force", action="store_true", help="replace sparse points the scene already has")
    parser.add_argument("--seed", type=int, default=0, help="seed of every RANSAC in verification and triangulation: "
                                                             "same machine + same seed, same points (default 0)")


def run(args: argparse.Namespace) -> int:
    import numpy as np
    pycolmap = import_pycolmap()

    pycolmap.logging.minloglevel = pycolmap.logging.WARNING  # COLMAP's per-image INFO lines would bury the summary
    scene = load_scene(args.scene, layout=args.layout)
    if scene.has_points and not args.force:
        raise InputError(f"{args.scene}: the scene already has {len(scene.points)} sparse points "
                         f"({find_model_dir(args.scene)}); pass --force to replace them")
    if scene.meta.get("distorted_images"):
        raise InputError(f"{args.scene}: {scene.meta['distorted_images']} images use a distorted camera model; "
                         "undistort the scene first (colmap image_undistorter), the points model is pinhole")
    tri = triangulate_scene(scene, seed=args.seed)
    if len(tri.points) == 0:
        raise InputError(f"{args.scene}: no point could be triangulated from {len(tri.views)} training views "
                         f"({tri.meta['keypoints']} SIFT keypoints, {tri.meta['verified_pairs']} verified pairs)")
    errs = tri.reprojection_errors(scene.cameras)
    model_dir = write_points(scene, tri, args.scene)
    track = np.array([len(o) for o in tri.observations])
    summary = {**tri.meta, "points": len(tri.points), "observations": int(errs.size),
               "mean_track_length": float(track.mean()), "mean_reprojection_error_px": float(np.mean(errs)),
               "max_reprojection_error_px": float(np.max(errs)), "poses_from": scene.meta.get("poses_from")}
    write_json_atomic(args.scene / "sparse" / "points_provenance.json", summary)
    print(f"wrote {len(tri.points)} points to {model_dir} from {len(tri.views)} training views: mean track length "
          f"{summary['mean_track_length']:.2f}, reprojection error mean {summary['mean_reprojection_error_px']:.3f} px "
          f"(max {summary['max_reprojection_error_px']:.3f} px over {errs.size} observations); "
          f"points digest {summary['points_digest']} (seed {args.seed})")
    return 0
