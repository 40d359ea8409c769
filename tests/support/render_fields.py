"""Random Gaussian fields and look-at cameras for the render tests."""
from __future__ import annotations

import math

import numpy as np
import torch

from gsbench.camera import Camera
from gsbench.gaussians import GaussianField


def look_at(W: int, H: int, eye, target=(0.0, 0.0, 0.0), f: float | None = None, fy_ratio: float = 1.0,
            cx_off: float = 0.0, cy_off: float = 0.0) -> Camera:
    """OpenCV camera at `eye` looking at `target` (world up +y)."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 1.0, 0.0])
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    w2c = np.eye(4)
    w2c[:3, :3], w2c[:3, 3] = R, -R @ eye
    f = 0.9 * W if f is None else f
    K = np.array([[f, 0, W / 2 + cx_off], [0, f * fy_ratio, H / 2 + cy_off], [0, 0, 1]])
    return Camera(K, w2c, W, H)


def random_field(n: int, seed: int, *, d: int = 3, sh_degree: int | None = None, scale=(0.03, 0.3),
                 dtype=torch.float64, spread: float = 1.0) -> GaussianField:
    g = torch.Generator().manual_seed(seed)

    def r(*shape):
        return torch.rand(*shape, generator=g, dtype=torch.float64)

    lo, hi = math.log(scale[0]), math.log(scale[1])
    colors = r(n, 3) if sh_degree is None else (r(n, (sh_degree + 1) ** 2, 3) - 0.5)
    field = GaussianField(
        means=(r(n, 3) - 0.5) * 2 * spread,
        log_scales=lo + (hi - lo) * r(n, 3),
        quats=torch.randn(n, 4, generator=g, dtype=torch.float64),
        opacity_logits=torch.randn(n, generator=g, dtype=torch.float64) * 2,
        colors=colors,
        features=(torch.randn(n, d, generator=g, dtype=torch.float64) if d else None),
    )
    return field.to(dtype=dtype)


def with_grad(field: GaussianField) -> GaussianField:
    return GaussianField(**{k: (None if v is None else v.detach().clone().requires_grad_(True))
                            for k, v in field.tensors().items()})
