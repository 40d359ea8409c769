"""Sparse points for scenes that have poses but no points (LLFF / NeRF captures, generated scenes).

Training initialises from sparse points where a scene has them; without them it falls back to
random points. This module recovers points the way COLMAP's `point_triangulator` does: SIFT
features of the training views, exhaustive matching with geometric verification, then
triangulation from the KNOWN poses (no pose is estimated or refined). All of it runs in pycolmap
on the CPU. Only training views are used, so no held-out view informs the initialisation.

The points are reproducible on one machine for a given seed: the two-view RANSAC, whose default seed
is drawn afresh each run, is the part that varied (1,629-1,643 points on dtu_scan37 in one session),
so every RANSAC and the global PRNG are seeded and every stage runs on one thread, which fixes the
order in which pairs are matched and verified. `points_digest` (datasets.base.point_set_digest) tells
two point sets apart, and every run records it.
"""
from __future__ import annotations

import logging
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gsbench.camera import Camera
from gsbench.colmap_lib import import_pycolmap
from gsbench.errors import InputError

from .base import Scene, point_set_digest
from .colmap import write_colmap

log = logging.getLogger(__name__)


@dataclass
class Triangulation:
    """Triangulated points with their observations (for the reprojection check) and provenance."""

    points: np.ndarray                 # (M, 3) world coordinates
    colors: np.ndarray                 # (M, 3) in [0, 1]
    observations: list[list[tuple[int, np.ndarray]]]  # per point: (camera index, observed pixel xy)
    views: list[int]                   # camera indices the features came from
    meta: dict = field(default_factory=dict)

    def reprojection_errors(self, cameras: list[Camera]) -> np.ndarray:
        """Pixel distance between each observation and its point projected by OUR camera model.

        Computed here rather than read from COLMAP so that it also checks that the two agree on
        pose and pixel conventions."""
        errs = []
        for p, obs in zip(self.points, self.observations):
            for ci, xy in obs:
                uv, z = cameras[ci].project(p[None])
                errs.append(float(np.linalg.norm(uv[0] - xy)) if z[0] > 0 else np.inf)
        return np.asarray(errs, dtype=np.float64)


def _image_dir(scene: Scene, views: list[int]) -> Path:
    """The one folder holding the views' images (pycolmap reads images by name relative to it)."""
    dirs = {Path(scene.image_paths[i]).parent for i in views}
    if len(dirs) != 1:
        raise InputError(f"{scene.path}: the training images lie in {len(dirs)} folders; one is needed")
    return dirs.pop()


def _seeded_options(seed: int) -> tuple:
    """Extraction, matching, verification and triangulation options that give the same points every run.

    One thread everywhere: threads take pairs in a varying order, and the matcher is not guaranteed to
    give the same matches then. Measured on dtu_scan37 (42 views, 2 cores under load): 8.8-10.5 s
    against 8.1-8.7 s with the former 2 threads and unseeded verification."""
    pycolmap = import_pycolmap()

    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = 1
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = 1
    verification = pycolmap.TwoViewGeometryOptions()
    verification.ransac.random_seed = seed  # default -1: a fresh seed every run
    verification.ransac.num_threads = 1
    pipeline = pycolmap.IncrementalPipelineOptions()
    pipeline.num_threads = 1
    pipeline.random_seed = seed
    pipeline.mapper.num_threads = 1
    pipeline.mapper.random_seed = seed
    pipeline.triangulation.random_seed = seed
    return extraction, matching, verification, pipeline


def triangulate_scene(scene: Scene, views: list[int] | None = None, seed: int = 0) -> Triangulation:
    """SIFT + exhaustive matching + triangulation from the scene's poses, on `views` (default: train views)."""
    pycolmap = import_pycolmap()

    views = list(scene.train_ids if views is None else views)
    if len(views) < 2:
        raise InputError(f"{scene.path}: triangulation needs at least two posed training views, the scene has "
                         f"{len(views)}")
    img_dir = _image_dir(scene, views)
    names = [Path(scene.image_paths[i]).name for i in views]
    cams = [scene.cameras[i] for i in views]
    with tempfile.TemporaryDirectory(prefix="gsbench-points-") as tmp:
        tmp = Path(tmp)
        write_colmap(tmp / "posed", cams, names)  # the known poses, no points
        rec = pycolmap.Reconstruction(str(tmp / "posed"))
        db_path = tmp / "database.db"
        # The database must carry the model's ids, so that matches refer to the posed images.
        with pycolmap.Database.open(str(db_path)) as db:
            for cam in rec.cameras.values():
                db.write_camera(cam, use_camera_id=True)
            for rig in rec.rigs.values():
                db.write_rig(rig, use_rig_id=True)
            for frame in rec.frames.values():
                db.write_frame(frame, use_frame_id=True)
            for im in rec.images.values():
                db.write_image(im, use_image_id=True)
        cpu = pycolmap.Device.cpu
        extraction, matching, verification, options = _seeded_options(seed)
        pycolmap.set_random_seed(seed)
        pycolmap.extract_features(db_path, img_dir, image_names=names, extraction_options=extraction, device=cpu)
        pycolmap.match_exhaustive(db_path, matching_options=matching, verification_options=verification, device=cpu)
        with pycolmap.Database.open(str(db_path)) as db:
            n_kp, n_pairs = int(db.num_keypoints()), int(db.num_verified_image_pairs())
        (tmp / "out").mkdir()
        out = pycolmap.triangulate_points(rec, db_path, img_dir, tmp / "out", clear_points=True, options=options)
    view_of = {im_id: views[names.index(im.name)] for im_id, im in out.images.items()}
    pts, cols, obs = [], [], []
    for _, p3d in sorted(out.points3D.items()):
        pts.append(np.asarray(p3d.xyz, dtype=np.float64))
        cols.append(np.asarray(p3d.color, dtype=np.float64) / 255.0)
        obs.append([(view_of[e.image_id], np.asarray(out.images[e.image_id].points2D[e.point2D_idx].xy, np.float64))
                    for e in p3d.track.elements])
    points, colors = np.reshape(np.asarray(pts), (-1, 3)), np.reshape(np.asarray(cols), (-1, 3))
    meta = {"source": "pycolmap SIFT + exhaustive matching + triangulate_points (known poses, CPU)",
            "pycolmap": str(pycolmap.__version__), "views": len(views), "keypoints": n_kp,
            "verified_pairs": n_pairs, "seed": seed, "deterministic": True, "threads": 1,
            "points_digest": point_set_digest(points)}
    log.info("triangulated %d points from %d views (%d keypoints, %d verified pairs)", len(pts), len(views), n_kp,
             n_pairs)
    return Triangulation(points, colors, obs, views, meta)


def write_points(scene: Scene, tri: Triangulation, root: Path) -> Path:
    """`root/sparse/0`: a COLMAP model with every camera of the scene (train and test) and the points.

    A COLMAP model names its images relative to `root/images` (that is where the loader looks), so a
    scene whose images lie elsewhere is refused rather than left with a model that cannot load."""
    img_dir = (Path(root) / "images").resolve()
    outside = [p for p in scene.image_paths if Path(p).resolve().parent != img_dir]
    if outside:
        raise InputError(f"{outside[0]}: a COLMAP model needs every image directly in {img_dir} "
                         f"({len(outside)} images are elsewhere)")
    names = [Path(p).name for p in scene.image_paths]
    model_dir = Path(root) / "sparse" / "0"
    write_colmap(model_dir, scene.cameras, names, tri.points, tri.colors)
    return model_dir
