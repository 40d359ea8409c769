"""Compile the CPU backend's and the SSIM loss's numba kernels for one dtype into numba's on-disk
cache: `python numba_warmup.py float32`.

Why: on a fresh clone the cache is empty, and every pytest-xdist worker that renders first compiles
the same kernels at the same time (about 45 s of one core for both dtypes, paid once per worker).
tests/conftest.py runs this once per dtype, the two processes side by side, before the workers
start; the workers then load the kernels from the cache. With a warm cache it takes about a second.
"""
from __future__ import annotations

import sys

import gsbench  # noqa: F401  (before torch: gsbench's OpenMP settings)

# isort: split
import numpy as np
import torch

from gsbench.camera import Camera
from gsbench.gaussians import GaussianField
from gsbench.methods.losses import ssim
from gsbench.render import render


def warm(dtype: torch.dtype) -> None:
    """One forward+backward render with features, a no-grad render and one SSIM forward+backward."""
    g = torch.Generator().manual_seed(0)
    n, w, h = 64, 24, 16
    z = torch.rand(n, generator=g, dtype=dtype) * 2.0 + 2.0
    means = torch.stack([(torch.rand(n, generator=g, dtype=dtype) - 0.5) * z,
                         (torch.rand(n, generator=g, dtype=dtype) - 0.5) * z, z], 1)
    tensors = dict(means=means, log_scales=torch.full((n, 3), -2.5, dtype=dtype),
                   quats=torch.randn(n, 4, generator=g, dtype=dtype),
                   opacity_logits=torch.zeros(n, dtype=dtype),
                   colors=torch.rand(n, 3, generator=g, dtype=dtype),
                   features=torch.rand(n, 3, generator=g, dtype=dtype))
    K = np.array([[float(w), 0.0, w / 2.0], [0.0, float(w), h / 2.0], [0.0, 0.0, 1.0]])
    camera = Camera(K, np.eye(4), w, h)
    field = GaussianField(**{k: v.requires_grad_(True) for k, v in tensors.items()})
    out = render(field, camera, backend="cpu")
    loss = out.rgb.sum() + out.depth.sum() + out.alpha.sum() + out.features.sum()
    loss = loss + ssim(out.rgb, torch.full_like(out.rgb, 0.5).detach())
    loss.backward()
    with torch.no_grad():
        render(field, camera, backend="cpu")


if __name__ == "__main__":
    warm(getattr(torch, sys.argv[1]))
