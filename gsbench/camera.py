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


def training_size(camera: Camera, max_width: Optional[int]) -> tuple[int, int]:
    """(W, H) of the training images: the camera's size, downscaled to at most `max_width` wide (the
    rule training and evaluation at the training resolution share, so it sits beside Camera)."""
    w, h = camera.width, camera.height
    if max_width and w > int(max_width):
        s = int(max_width) / w
        return int(max_width), max(1, int(round(h * s)))
    return w, h
