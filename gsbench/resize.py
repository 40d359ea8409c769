"""Every resize of gsbench, in one place, each named by what it does and with one convention: the
target size is given as (width, height), and an array already at that size comes back unchanged.

- `resize_rgb`: an RGB image as 3DGS loads its images (the 8-bit image through PIL's bicubic filter):
  training images and the evaluation's GT alike.
- `resize_nearest`: labels, instance / class maps, masks and depth maps, by centre sampling: the
  source pixel under each target pixel's centre, as PIL NEAREST (the 3D-OVS reference) picks it;
  any dtype, kept (bool in, bool out), values never mixed.
- `resize_area`: an image brought to a priors' working size by area averaging (the inputs of the
  weight-free priors and the report's small pictures).
"""
from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from gsbench.errors import InputError

RGB_IMPL = "pil-bicubic-uint8"
NEAREST_IMPL = "nearest/centre-sampling/cv2-INTER_NEAREST_EXACT"


def resize_rgb(img: np.ndarray, width: int, height: int) -> np.ndarray:
    """float32 RGB in [0, 1] at width x height, resized as 3DGS loads its images: the 8-bit image
    through PIL's bicubic filter (Image.resize's default for RGB), then / 255. Channels after the
    third (alpha) are dropped; the same size is returned unchanged."""
    from PIL import Image

    a = np.asarray(img)
    if a.ndim != 3 or a.shape[2] < 3:
        raise InputError(f"resize_rgb: expected an H x W x 3 image, got shape {a.shape}")
    a = a[..., :3]
    if a.shape[1] == width and a.shape[0] == height:
        return a
    q = np.floor(np.clip(a, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    out = Image.fromarray(q, "RGB").resize((int(width), int(height)), Image.Resampling.BICUBIC)
    return np.asarray(out, dtype=np.float32) / np.float32(255.0)


def _source_index(n_src: int, n_dst: int) -> np.ndarray:
    """For each of n_dst target pixels along one axis, the source pixel under its centre, exactly as
    cv2.INTER_NEAREST_EXACT (= PIL NEAREST) picks it: resize the source's index ramp (exact in float32)."""
    ramp = np.arange(n_src, dtype=np.float32).reshape(1, n_src)
    return cv2.resize(ramp, (int(n_dst), 1), interpolation=cv2.INTER_NEAREST_EXACT)[0].astype(np.int64)


def resize_nearest(a: Any, width: int, height: int) -> np.ndarray:
    """An (H, W) map of any dtype at width x height by centre sampling (module docstring). A torch
    tensor is read as an array."""
    if hasattr(a, "detach"):
        a = a.detach().cpu().numpy()
    arr = np.asarray(a)
    if arr.ndim != 2:
        raise InputError(f"resize_nearest: expected an (H, W) array, got shape {arr.shape}")
    if width < 1 or height < 1:
        raise InputError(f"resize_nearest: target size {width}x{height} is not positive")
    if arr.shape == (height, width):
        return arr
    ys = _source_index(arr.shape[0], height)
    xs = _source_index(arr.shape[1], width)
    return arr[ys[:, None], xs[None, :]]


def resize_area(img: np.ndarray, width: int, height: int) -> np.ndarray:
    """An image (H, W) or (H, W, C) at width x height by area averaging (cv2.INTER_AREA)."""
    a = np.asarray(img)
    if a.shape[1] == width and a.shape[0] == height:
        return a
    return cv2.resize(a, (int(width), int(height)), interpolation=cv2.INTER_AREA)


__all__ = ["resize_rgb", "resize_nearest", "resize_area", "RGB_IMPL", "NEAREST_IMPL"]
