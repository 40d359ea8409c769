"""Camera: the one camera convention every part of gsbench uses.

OpenCV convention: x right, y down, z forward. `world_to_camera` maps homogeneous world
points to camera space. Readers convert other conventions (OpenGL/NeRF, LLFF, USD) on load;
nothing else converts.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np
import torch


def _as_array(x, shape: tuple[int, ...], name: str) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    a = np.asarray(x, dtype=np.float64)
    if a.shape != shape:
        raise ValueError(f"Camera.{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"Camera.{name} contains NaN or inf")
    return a


@dataclass
class Camera:
    """A pinhole camera: intrinsics `K` (3x3), `world_to_camera` (4x4), image size in pixels."""

    K: np.ndarray
    world_to_camera: np.ndarray
    width: int
    height: int
    name: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.K = _as_array(self.K, (3, 3), "K")
        self.world_to_camera = _as_array(self.world_to_camera, (4, 4), "world_to_camera")
        self.width = int(self.width)
        self.height = int(self.height)
        if self.width < 1 or self.height < 1:
            raise ValueError(f"Camera size must be positive, got {self.width}x{self.height}")
        self._tensor_cache: dict = {}

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["_tensor_cache"] = {}          # device tensors are never pickled
        return state

    def device_tensors(self, device, dtype=torch.float32) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(K, world_to_camera, centre) as tensors on `device`, copied once per device and dtype: a
        training step on CUDA then sends nothing from the host. Cameras are not mutated in place
        (resized/scaled return new ones), so the cache cannot go stale."""
        key = (str(device), dtype)
        hit = self._tensor_cache.get(key)
        if hit is None:
            hit = tuple(torch.as_tensor(np.asarray(a), dtype=dtype).to(device)
                        for a in (self.K, self.world_to_camera, self.center))
            self._tensor_cache[key] = hit
        return hit

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    @property
    def camera_to_world(self) -> np.ndarray:
        return np.linalg.inv(self.world_to_camera)

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates."""
        R = self.world_to_camera[:3, :3]
        t = self.world_to_camera[:3, 3]
        return -R.T @ t

    def scaled(self, factor: float) -> "Camera":
        """The same camera at an image resolution multiplied by `factor`."""
        K = self.K.copy()
        K[:2] *= factor
        w = max(1, int(round(self.width * factor)))
        h = max(1, int(round(self.height * factor)))
        return Camera(K, self.world_to_camera.copy(), w, h, self.name, dict(self.meta))

    def resized(self, width: int, height: int) -> "Camera":
        """The same camera rendered at `width` x `height` (independent x/y scale)."""
        K = self.K.copy()
        K[0] *= width / self.width
        K[1] *= height / self.height
        return Camera(K, self.world_to_camera.copy(), width, height, self.name, dict(self.meta))

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points (N x 3) -> pixel coordinates (N x 2, pixel centres at +0.5) and depth z."""
        p = np.asarray(points, dtype=np.float64)
        pc = p @ self.world_to_camera[:3, :3].T + self.world_to_camera[:3, 3]
        z = pc[:, 2]
        zs = np.where(np.abs(z) < 1e-12, 1e-12, z)
        uv = np.stack([self.fx * pc[:, 0] / zs + self.cx, self.fy * pc[:, 1] / zs + self.cy], axis=1)
        return uv, z

    def to_dict(self) -> dict:
        return {"K": self.K.tolist(), "world_to_camera": self.world_to_camera.tolist(),
                "width": self.width, "height": self.height, "name": self.name}

    @classmethod
    def from_dict(cls, d: dict) -> "Camera":
        return cls(np.array(d["K"]), np.array(d["world_to_camera"]), d["width"], d["height"], d.get("name", ""))


# --------------------------------------------------------------------------------- the camera check
ROTATION_TOL = 1e-3   # largest |R R^T - I| entry and |det R - 1| of a pose rotation still taken as one


def intrinsics_problems(K, width: int, height: int) -> list[str]:
    """Why `K` (3x3 pixels) cannot be a pinhole camera of a width x height image; empty when it can.

    The one check every layout reader runs (`gsbench.datasets.base.build_cameras`): finite values,
    focal lengths > 0 (a zero one divides by zero in the projection, a negative one mirrors the
    image), the principal point inside the image."""
    if int(width) < 1 or int(height) < 1:
        return [f"image size {width}x{height} is not positive"]
    k = np.asarray(K, dtype=np.float64)
    if k.shape != (3, 3):
        return [f"intrinsics have shape {k.shape}, not 3x3"]
    if not np.all(np.isfinite(k)):
        return ["intrinsics hold NaN or inf"]
    out = []
    for name, f in (("fx", k[0, 0]), ("fy", k[1, 1])):
        if not f > 0:
            out.append(f"focal length {name}={f:.6g} is not positive")
    cx, cy = k[0, 2], k[1, 2]
    if not (0 <= cx <= width and 0 <= cy <= height):
        out.append(f"principal point ({cx:.6g}, {cy:.6g}) lies outside the {width}x{height} image")
    return out


def pose_problems(world_to_camera) -> list[str]:
    """Why a 4x4 world-to-camera matrix is not a rigid pose; empty when it is.

    Finite values, last row [0, 0, 0, 1], and a proper rotation: orthonormal (every entry of R R^T
    within ROTATION_TOL of the identity) with det R within ROTATION_TOL of +1. A rank-deficient,
    scaled or mirrored rotation renders a distorted scene without any error, so it is refused."""
    m = np.asarray(world_to_camera, dtype=np.float64)
    if m.shape != (4, 4):
        return [f"pose has shape {m.shape}, not 4x4"]
    if not np.all(np.isfinite(m)):
        return ["pose holds NaN or inf"]
    out = []
    if np.max(np.abs(m[3] - [0.0, 0.0, 0.0, 1.0])) > ROTATION_TOL:
        out.append(f"pose's last row is {np.array2string(m[3], precision=3)}, not [0 0 0 1]")
    R = m[:3, :3]
    with np.errstate(over="ignore", invalid="ignore"):    # a huge entry gives inf: still not a rotation
        err = float(np.max(np.abs(R @ R.T - np.eye(3))))
        det = float(np.linalg.det(R))
    if not (err <= ROTATION_TOL and abs(det - 1.0) <= ROTATION_TOL):
        out.append(f"rotation is not a proper rotation: det {det:.3g} (must be 1 +- {ROTATION_TOL:g}), "
                   f"R R^T off the identity by up to {err:.3g} (at most {ROTATION_TOL:g})")
    return out


def quaternion_matrix(wxyz) -> np.ndarray:
    """3x3 matrix of a quaternion (w, x, y, z) in the homogeneous form, without normalising: a unit
    quaternion gives its rotation, one of norm s gives s^2 times it and the zero quaternion the zero
    matrix, so the pose check refuses a quaternion that is not a unit one (normalising readers turn
    zero into the identity)."""
    w, x, y, z = (float(v) for v in wxyz)
    return np.array([
        [w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z]])


def training_size(camera: Camera, max_width: Optional[int]) -> tuple[int, int]:
    """(W, H) of the training images: the camera's size, downscaled to at most `max_width` wide (the
    rule training and evaluation at the training resolution share, so it sits beside Camera)."""
    w, h = camera.width, camera.height
    if max_width and w > int(max_width):
        s = int(max_width) / w
        return int(max_width), max(1, int(round(h * s)))
    return w, h
