"""COLMAP sparse models (binary or text) through pycolmap: read cameras + points, write a model.

COLMAP's `cam_from_world` is already the OpenCV world-to-camera transform, so no axis change.
Pixel convention: COLMAP puts the centre of the top-left pixel at (0.5, 0.5), as gsbench does.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from gsbench.camera import ROTATION_TOL, Camera, quaternion_matrix
from gsbench.colmap_lib import import_pycolmap
from gsbench.errors import InputError, shorten

from .guard import RawCamera, build_cameras

# model name -> (fx, fy, cx, cy) parameter indices; the rest are distortion parameters
_PINHOLE_LIKE = {
    "SIMPLE_PINHOLE": (0, 0, 1, 2), "PINHOLE": (0, 1, 2, 3),
    "SIMPLE_RADIAL": (0, 0, 1, 2), "RADIAL": (0, 0, 1, 2),
    "OPENCV": (0, 1, 2, 3), "FULL_OPENCV": (0, 1, 2, 3), "OPENCV_FISHEYE": (0, 1, 2, 3),
    "SIMPLE_RADIAL_FISHEYE": (0, 0, 1, 2), "RADIAL_FISHEYE": (0, 0, 1, 2),
}
_UNDISTORTED = {"SIMPLE_PINHOLE", "PINHOLE"}


def find_model_dir(root: Path) -> Path | None:
    """The COLMAP model folder of a scene: sparse/0, sparse, or the folder itself."""
    root = Path(root)
    for cand in (root / "sparse" / "0", root / "sparse", root):
        for stem in ("cameras.bin", "cameras.txt"):
            if (cand / stem).is_file():
                return cand
    return None


def model_file(model_dir: Path, stem: str) -> Path:
    """The model's `stem`.bin, else `stem`.txt (the file a camera problem names)."""
    binary = model_dir / f"{stem}.bin"
    return binary if binary.is_file() else model_dir / f"{stem}.txt"


def _world_to_camera(im) -> np.ndarray:
    """4x4 world-to-camera of a COLMAP image. pycolmap normalises the stored quaternion when it makes
    the matrix (a zero quaternion reads as the identity), so a quaternion that is not a unit one is
    given to the shared pose check in its unnormalised homogeneous form, which the check refuses."""
    cfw = im.cam_from_world
    cfw = cfw() if callable(cfw) else cfw  # a method in pycolmap 4, a property before
    w2c = np.eye(4)
    w2c[:3, :4] = np.asarray(cfw.matrix(), dtype=np.float64)
    x, y, z, w = np.asarray(cfw.rotation.quat, dtype=np.float64)
    if not abs(float(np.sqrt(w * w + x * x + y * y + z * z)) - 1.0) <= ROTATION_TOL:
        w2c[:3, :3] = quaternion_matrix((w, x, y, z))
    return w2c


def _refuse_duplicate_names(rec, images_file: Path) -> None:
    """Two images of one name: the cameras are keyed by image name, so one pose would be dropped
    without a word (and which one would depend on the order of the ids)."""
    seen: dict[str, int] = {}
    for image_id, im in sorted(rec.images.items()):
        if im.name in seen:
            raise InputError(f"{images_file}: images {seen[im.name]} and {image_id} are both named "
                             f"{shorten(repr(im.name))}: each image needs its own name (its pose is looked up "
                             "by name); remove or rename one")
        seen[im.name] = image_id


def read_colmap(model_dir: Path) -> tuple[dict[str, Camera], np.ndarray | None, np.ndarray | None, dict]:
    """Cameras by image name, sparse points (M x 3), point colours (M x 3 in [0, 1]), meta."""
    pycolmap = import_pycolmap()

    model_dir = Path(model_dir)
    try:
        rec = pycolmap.Reconstruction(str(model_dir))
    except Exception as e:
        raise InputError(f"{model_dir}: cannot read COLMAP model ({type(e).__name__}: {e})") from None
    cams_file, images_file = (model_file(model_dir, stem) for stem in ("cameras", "images"))
    _refuse_duplicate_names(rec, images_file)
    raws: list[RawCamera] = []
    distorted = []
    for im in sorted(rec.images.values(), key=lambda im: im.name):
        if not getattr(im, "has_pose", True):  # pycolmap >= 3.12: frames may be unregistered
            continue
        c = im.camera
        model = str(c.model_name)
        if model not in _PINHOLE_LIKE:
            raise InputError(f"{model_dir}: image {im.name}: unsupported COLMAP camera model {model}")
        p = np.asarray(c.params, dtype=np.float64)
        ifx, ify, icx, icy = _PINHOLE_LIKE[model]
        K = np.array([[p[ifx], 0.0, p[icx]], [0.0, p[ify], p[icy]], [0.0, 0.0, 1.0]])
        meta = {"colmap_model": model}
        n_intr = 3 if ifx == ify else 4
        dist = p[n_intr:].tolist()
        if model not in _UNDISTORTED and any(abs(d) > 0 for d in dist):
            meta["distortion"] = {"model": model, "params": dist}
            distorted.append(im.name)
        raws.append(RawCamera(K, int(c.width), int(c.height), im.name, cams_file, images_file,
                              world_to_camera=_world_to_camera(im), meta=meta))
    cams = dict(zip((r.name for r in raws), build_cameras(raws)))
    if not cams:
        raise InputError(f"{model_dir}: COLMAP model has no registered images")
    meta = {"colmap_dir": str(model_dir), "num_points": int(rec.num_points3D())}
    if distorted:
        meta["distorted_images"] = len(distorted)
        warnings.warn(f"{model_dir}: {len(distorted)} images use a distorted camera model; gsbench renders "
                      "pinhole cameras, so undistort the images (colmap image_undistorter) for exact results",
                      stacklevel=2)
    points = colors = None
    if rec.num_points3D() > 0:
        pts = sorted(rec.points3D.items())
        points = np.array([pt.xyz for _, pt in pts], dtype=np.float64)
        colors = np.array([pt.color for _, pt in pts], dtype=np.float64) / 255.0
        bad = int((~np.isfinite(points)).any(axis=1).sum())
        if bad:
            raise InputError(f"{model_file(model_dir, 'points3D')}: {bad} of {len(points)} sparse points "
                             "hold NaN or inf")
    return cams, points, colors, meta


def write_colmap(model_dir: Path, cameras: list[Camera], names: list[str], points: np.ndarray | None = None,
                 colors: np.ndarray | None = None, binary: bool = True) -> None:
    """Write a PINHOLE COLMAP model (one camera per image) with optional coloured points.
    Uses the rig / frame API of pycolmap >= 3.12."""
    pycolmap = import_pycolmap()

    model_dir = Path(model_dir)
    model_dir.mkdir(parents=True, exist_ok=True)
    rec = pycolmap.Reconstruction()
    for i, (cam, name) in enumerate(zip(cameras, names)):
        c = pycolmap.Camera.create_from_model_name(i + 1, "PINHOLE", cam.fx, cam.width, cam.height)
        c.params = [cam.fx, cam.fy, cam.cx, cam.cy]
        rec.add_camera_with_trivial_rig(c)
        im = pycolmap.Image(name=name, camera_id=i + 1, image_id=i + 1)
        rec.add_image_with_trivial_frame(im, pycolmap.Rigid3d(cam.world_to_camera[:3, :4].copy()))
    if points is not None:
        cols = np.zeros((len(points), 3)) if colors is None else np.asarray(colors)
        cols8 = np.clip(np.round(cols * 255), 0, 255).astype(np.uint8)
        for xyz, col in zip(np.asarray(points, dtype=np.float64), cols8):
            rec.add_point3D(xyz, pycolmap.Track(), col)
    tmp = model_dir.parent / f".{model_dir.name}.tmp"
    tmp.mkdir(parents=True, exist_ok=True)
    if binary:
        rec.write_binary(str(tmp))
    else:
        rec.write_text(str(tmp))
    for f in tmp.iterdir():  # per-file rename: each model file appears whole
        f.replace(model_dir / f.name)
    tmp.rmdir()
