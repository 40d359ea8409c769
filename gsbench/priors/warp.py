"""Geometry shared by the priors: resizing, unprojection and z-buffered splatting.

Pixel convention (as `Camera.project`): pixel (x, y) covers [x, x+1) x [y, y+1) and its centre
is at (x + 0.5, y + 0.5).
"""
from __future__ import annotations

import numpy as np

from gsbench.camera import Camera

NEAR = 1e-6


def camera_at(cam: Camera, size: tuple[int, int]) -> Camera:
    """`cam` at resolution `size` = (W, H)."""
    W, H = size
    if cam.width == W and cam.height == H:
        return cam
    return cam.resized(W, H)


def unproject(depth: np.ndarray, valid: np.ndarray, cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    """World points (M, 3) of the valid pixels of a camera-space z map, and their flat indices."""
    H, W = depth.shape
    ok = valid & np.isfinite(depth) & (depth > NEAR)
    flat = np.flatnonzero(ok)
    ys, xs = np.divmod(flat, W)
    z = depth.reshape(-1)[flat].astype(np.float64)
    x = (xs + 0.5 - cam.cx) / cam.fx * z
    y = (ys + 0.5 - cam.cy) / cam.fy * z
    pc = np.stack([x, y, z], axis=1)
    R = cam.world_to_camera[:3, :3]
    t = cam.world_to_camera[:3, 3]
    return (pc - t) @ R, flat


def zbuffer_splat(points: np.ndarray, values: np.ndarray, cam: Camera, fill) -> tuple[np.ndarray, np.ndarray]:
    """Project world points into `cam`; each pixel keeps the value of its nearest point.

    Returns (value map HxW filled with `fill` where no point lands, z map HxW with +inf there).
    """
    W, H = cam.width, cam.height
    out = np.full((H, W), fill, dtype=values.dtype)
    zmap = np.full((H, W), np.inf, dtype=np.float64)
    if len(points) == 0:
        return out, zmap
    uv, z = cam.project(points)
    ok = np.isfinite(uv).all(axis=1) & np.isfinite(z) & (z > NEAR)
    ix = np.floor(uv[:, 0]).astype(np.int64, copy=False)
    iy = np.floor(uv[:, 1]).astype(np.int64, copy=False)
    ok &= (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H)
    if not ok.any():
        return out, zmap
    pix = iy[ok] * W + ix[ok]
    zz = z[ok]
    vv = values[ok]
    order = np.lexsort((zz, pix))          # by pixel, nearest first
    first = np.unique(pix[order], return_index=True)[1]
    sel = order[first]
    out.reshape(-1)[pix[sel]] = vv[sel]
    zmap.reshape(-1)[pix[sel]] = zz[sel]
    return out, zmap


def reproject_labels(labels: np.ndarray, depth: np.ndarray, valid: np.ndarray,
                     src: Camera, dst: Camera) -> np.ndarray:
    """Forward-warp an int label map from `src` into `dst` with a z-buffer (-1 where nothing lands)."""
    pts, flat = unproject(depth, valid, src)
    vals = labels.reshape(-1)[flat].astype(np.int32)
    # Unlabelled surface points still occlude: they are splatted as -1 and hide labels behind them.
    out, _ = zbuffer_splat(pts, vals, dst, fill=np.int32(-1))
    return out


def coverage(depth: np.ndarray, valid: np.ndarray, src: Camera, dst: Camera) -> np.ndarray:
    """Bool map of the `dst` pixels that receive a surface point of `src` (the shared view region)."""
    pts, _ = unproject(depth, valid, src)
    _, zmap = zbuffer_splat(pts, np.zeros(len(pts), dtype=np.int8), dst, fill=np.int8(0))
    return np.isfinite(zmap)
