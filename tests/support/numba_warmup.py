"""Compile the CPU backend's and the CPU losses' numba kernels (SSIM, gsbench/train/losses_cpu.py) for one
dtype into numba's on-disk cache: `python numba_warmup.py float32`.

Why: on a fresh clone the cache is empty, and every pytest-xdist worker that renders first compiles
the same kernels at the same time (about 45 s of one core for both dtypes, paid once per worker).
tests/conftest.py runs this once per dtype, the two processes side by side, before the workers
start; the workers then load the kernels from the cache. With a warm cache it takes about a second.
"""
from __future__ import annotations

import sys

import gsbench  # noqa: F401  (before torch: gsbench's OpenMP settings)

# isort: split
import torch
from render_fields import look_at, random_field, with_grad

from gsbench.render import render
from gsbench.train import losses as L


def warm(dtype: torch.dtype) -> None:
    """One forward+backward render with features through GaussianDS's losses, and a no-grad render."""
    field = with_grad(random_field(64, 0, dtype=dtype))
    camera = look_at(24, 16, eye=(0.0, 0.0, -3.0))
    out = render(field, camera, backend="cpu")
    loss = out.rgb.sum() + out.depth.sum() + out.alpha.sum() + out.features.sum()
    loss = loss + L.ssim(out.rgb, torch.full_like(out.rgb, 0.5).detach())
    dn = L.normalised_depth(out.depth, out.alpha)
    prior = torch.rand(out.depth.shape, dtype=dtype, generator=torch.Generator().manual_seed(0)) + 0.5
    for kind in ("disparity", "depth"):
        loss = loss + L.depth_loss("scale_shift", L.expected_depth(dn, out.alpha), prior, prior > 0.7, kind).loss
    has = torch.ones(out.depth.shape, dtype=torch.bool)
    target = torch.zeros_like(out.features)
    loss = (loss + L.tv_loss(dn) + L.sem_loss(out.features, target, has)
            + L.ds_loss(out.features, target, has, prior > 1.2) + L.ds_loss(out.features, target, has, has, "edges"))
    loss.backward()
    with torch.no_grad():
        render(field, camera, backend="cpu")


if __name__ == "__main__":
    warm(getattr(torch, sys.argv[1]))
