"""LLFF `poses_bounds.npy`: N x 17 rows = a 3 x 5 matrix (camera-to-world 3 x 4 + [H, W, focal]) and
(near, far) bounds.

LLFF rotation columns are [down, right, back] (the imgs2poses convention). OpenCV camera-to-world
columns are [right, down, forward] = [col1, col0, -col2]. The focal length is in pixels at (H, W);
the principal point is the image centre.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from gsbench.camera import Camera
from gsbench.errors import InputError

from .guard import RawCamera, build_cameras
from .imageio import read_npy, write_npy


def llff_to_opencv_c2w(m: np.ndarray) -> np.ndarray:
    """3 x 4 LLFF camera-to-world -> 4 x 4 OpenCV camera-to-world."""
    c2w = np.eye(4)
    c2w[:3, 0] = m[:, 1]
    c2w[:3, 1] = m[:, 0]
    c2w[:3, 2] = -m[:, 2]
    c2w[:3, 3] = m[:, 3]
    return c2w


def opencv_to_llff_c2w(c2w: np.ndarray) -> np.ndarray:
    """4 x 4 OpenCV camera-to-world -> 3 x 4 LLFF [down, right, back, t]."""
    m = np.zeros((3, 4))
    m[:, 0] = c2w[:3, 1]
    m[:, 1] = c2w[:3, 0]
    m[:, 2] = -c2w[:3, 2]
    m[:, 3] = c2w[:3, 3]
    return m


def read_poses_bounds(
    path: Path, image_sizes: list[tuple[int, int]], names: list[str]
) -> tuple[list[Camera], np.ndarray]:
    """Cameras (scaled to the actual image sizes) and the (N, 2) near/far bounds."""
    path = Path(path)
    arr = read_npy(path)
    if arr.dtype.kind not in "fiu" or arr.ndim != 2 or arr.shape[1] != 17:
        raise InputError(f"{path}: expected an N x 17 array of numbers, got {arr.dtype} of shape {arr.shape}")
    if len(arr) != len(image_sizes):
        raise InputError(f"{path}: {len(arr)} poses but {len(image_sizes)} images")
    if not np.all(np.isfinite(arr[:, 15:17])):
        raise InputError(f"{path}: near / far bounds hold NaN or inf")
    raws = []
    for row, (w, h), name in zip(arr, image_sizes, names):
        m = row[:15].reshape(3, 5)
        H0, W0, f = m[:, 4]
        if not (H0 > 0 and W0 > 0):     # the image size the focal length is given at: divided by below
            raise InputError(f"{path}: pose of {name} has a non-positive or non-finite H, W ({H0}, {W0})")
        sx, sy = w / W0, h / H0
        if abs(sx - sy) > 0.01 * max(sx, sy):
            raise InputError(f"{path}: image {name} is {w}x{h}, poses say {W0:g}x{H0:g} (different aspect ratio)")
        K = np.array([[f * sx, 0.0, w / 2.0], [0.0, f * sy, h / 2.0], [0.0, 0.0, 1.0]])
        raws.append(RawCamera(K, w, h, name, path, path, camera_to_world=llff_to_opencv_c2w(m[:, :4])))
    cams = build_cameras(raws)
    return cams, arr[:, 15:17].copy()


def write_poses_bounds(path: Path, cameras: list[Camera], bounds: np.ndarray) -> None:
    """Write cameras with fx == fy and a centred principal point (what LLFF can express)."""
    rows = []
    for cam in cameras:
        if (
            abs(cam.fx - cam.fy) > 1e-9 * cam.fx
            or abs(cam.cx - cam.width / 2) > 1e-9
            or abs(cam.cy - cam.height / 2) > 1e-9
        ):
            raise ValueError(f"camera {cam.name}: LLFF needs fx == fy and a centred principal point")
        m = np.zeros((3, 5))
        m[:, :4] = opencv_to_llff_c2w(cam.camera_to_world)
        m[:, 4] = [cam.height, cam.width, cam.fx]
        rows.append(m.ravel())
    arr = np.concatenate([np.array(rows), np.asarray(bounds, dtype=np.float64).reshape(-1, 2)], axis=1)
    write_npy(path, arr)
