"""Ordering metrics for the pseudo-video (GAUSSIANDS.md, part 1).

`mean_adjacent_distance`: mean Euclidean distance between the camera centres of neighbouring
frames of the chain (lower = smoother video).

`adjacent_mask_iou`: how consistent the propagated track ids are between neighbouring frames.
For each neighbouring pair (t, t+1), frame t's track-id map is warped into frame t+1 by a
forward z-buffer splat:
  - every pixel of t with a valid depth (finite, > 0; depth = camera-space z, the rendered
    depth convention) is back-projected through its pixel centre (j + 0.5, i + 0.5), moved to
    frame t+1's camera and projected; it lands in pixel (floor(v), floor(u)).
  - points behind the t+1 camera (z <= 1e-6) or outside the image are dropped; when t+1 has a
    valid depth at the landing pixel, points more than `occlusion_tol` (relative) behind it are
    dropped as occluded.
  - when several points land in one pixel, the nearest (smallest z) wins (z-buffer).
Pixels of t+1 that receive no point are "uncovered" and not compared. For every track id >= 0
present in both frames, IoU = |W=k & M=k| / |(W=k | M=k) & covered|; an id whose union inside
the covered region is empty cannot be compared and is counted in `n_excluded`.
The metric is the plain mean over all compared (pair, id) IoUs; None when there is none.
Pure numpy.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from gsbench.errors import InputError

from ._common import finite_float, mean_or_none, to_numpy

ORDERING_DISTANCE_IMPL = "ordering/adjacent-centre-distance/v1"
ORDERING_MASK_IOU_IMPL = "ordering/adjacent-mask-iou/zbuffer-splat/v1"


def mean_adjacent_distance(centers: Any, order: Sequence[int]) -> float | None:
    """Mean |c[order[k+1]] - c[order[k]]| over the chain; None for fewer than two frames.

    centers: (N, 3) camera centres; order: indices into `centers` (each at most once).
    """
    c = finite_float(centers, "camera centres")
    if c.ndim != 2 or c.shape[1] != 3:
        raise InputError(f"camera centres: expected (N, 3), got {c.shape}")
    o = [int(i) for i in order]
    if len(set(o)) != len(o):
        raise InputError("order: repeats a view")
    if any(i < 0 or i >= len(c) for i in o):
        raise InputError(f"order: indices must lie in [0, {len(c) - 1}]")
    if len(o) < 2:
        return None
    p = c[o]
    return float(np.mean(np.linalg.norm(np.diff(p, axis=0), axis=1)))


def _camera(cam: Any, idx: int) -> tuple[np.ndarray, np.ndarray]:
    if hasattr(cam, "K") and hasattr(cam, "world_to_camera"):
        k, w2c = cam.K, cam.world_to_camera
    else:
        try:
            k, w2c = cam
        except (TypeError, ValueError):
            raise InputError(f"cameras[{idx}]: expected a Camera or a (K, world_to_camera) pair") from None
    k = finite_float(k, f"cameras[{idx}].K")
    w2c = finite_float(w2c, f"cameras[{idx}].world_to_camera")
    if k.shape != (3, 3) or w2c.shape != (4, 4):
        raise InputError(f"cameras[{idx}]: K must be 3x3 and world_to_camera 4x4, got {k.shape}, {w2c.shape}")
    if abs(np.linalg.det(k)) < 1e-12:
        raise InputError(f"cameras[{idx}]: K is singular")
    return k, w2c


def warp_track_ids(mask_a: np.ndarray, depth_a: np.ndarray, cam_a: tuple, cam_b: tuple,
                   shape_b: tuple[int, int], depth_b: np.ndarray | None = None,
                   occlusion_tol: float = 0.05) -> np.ndarray:
    """Frame a's ids splatted into frame b (see module docstring); -2 marks uncovered pixels."""
    ka, w2c_a = cam_a
    kb, w2c_b = cam_b
    h, w = mask_a.shape
    hb, wb = shape_b
    ii, jj = np.nonzero(np.isfinite(depth_a) & (depth_a > 0))
    out = np.full((hb, wb), -2, dtype=np.int64)
    if ii.size == 0:
        return out
    z = depth_a[ii, jj]
    pix = np.stack([jj + 0.5, ii + 0.5, np.ones_like(z)], axis=0)
    pc = (np.linalg.inv(ka) @ pix) * z                    # camera a, (3, n)
    c2w_a = np.linalg.inv(w2c_a)
    pw = c2w_a[:3, :3] @ pc + c2w_a[:3, 3:4]
    pb = w2c_b[:3, :3] @ pw + w2c_b[:3, 3:4]
    zb = pb[2]
    front = zb > 1e-6
    zs = np.where(front, zb, 1.0)
    uv = kb @ (pb / zs)
    col = np.floor(uv[0]).astype(np.int64)
    row = np.floor(uv[1]).astype(np.int64)
    keep = front & (col >= 0) & (col < wb) & (row >= 0) & (row < hb)
    if depth_b is not None:
        dt = np.full(zb.shape, np.nan)
        dt[keep] = depth_b[row[keep], col[keep]]
        visible_ok = ~(np.isfinite(dt) & (dt > 0)) | (zb <= dt * (1.0 + occlusion_tol))
        keep &= visible_ok
    if not np.any(keep):
        return out
    flat = row[keep] * wb + col[keep]
    zk = zb[keep]
    lab = mask_a[ii[keep], jj[keep]]
    orderz = np.lexsort((zk, flat))                     # by pixel, then nearest first
    flat_s = flat[orderz]
    first = np.ones(flat_s.size, dtype=bool)
    first[1:] = flat_s[1:] != flat_s[:-1]
    out.reshape(-1)[flat_s[first]] = lab[orderz][first]
    return out


def adjacent_mask_iou_pairs(masks_in_order: Sequence[Any], depths: Sequence[Any], cameras: Sequence[Any], *,
                            occlusion_tol: float = 0.05) -> list[dict]:
    """Per neighbouring pair: {"pair": (t, t+1), "ious": {track id: IoU}, "n_excluded": int}."""
    n = len(masks_in_order)
    if len(depths) != n or len(cameras) != n:
        raise InputError(f"adjacent_mask_iou: {n} masks but {len(depths)} depths and {len(cameras)} cameras")
    masks = []
    for t in range(n):
        m = to_numpy(masks_in_order[t], f"masks[{t}]")
        if m.ndim != 2 or not np.issubdtype(m.dtype, np.integer):
            raise InputError(f"masks[{t}]: expected an integer (H, W) track-id map, got {m.dtype} {m.shape}")
        d = to_numpy(depths[t], f"depths[{t}]").astype(np.float64)
        if d.shape != m.shape:
            raise InputError(f"depths[{t}] has shape {d.shape} but masks[{t}] has {m.shape}")
        masks.append((m.astype(np.int64), d, _camera(cameras[t], t)))
    out = []
    for t in range(n - 1):
        ma, da, ca = masks[t]
        mb, db, cb = masks[t + 1]
        warped = warp_track_ids(ma, da, ca, cb, mb.shape, db, occlusion_tol)
        covered = warped != -2
        shared = sorted(set(np.unique(ma[ma >= 0]).tolist()) & set(np.unique(mb[mb >= 0]).tolist()))
        ious: dict[int, float] = {}
        excluded = 0
        for k in shared:
            wk = warped == k
            mk = (mb == k) & covered
            union = int(np.count_nonzero(wk | mk))
            if union == 0:
                excluded += 1
                continue
            ious[int(k)] = int(np.count_nonzero(wk & mk)) / union
        out.append({"pair": (t, t + 1), "ious": ious, "n_excluded": excluded,
                    "covered_fraction": float(covered.mean())})
    return out


def adjacent_mask_iou(masks_in_order: Sequence[Any], depths: Sequence[Any], cameras: Sequence[Any], *,
                      occlusion_tol: float = 0.05) -> float | None:
    """Mean IoU of shared track ids between neighbouring frames after depth warping (see module doc)."""
    pairs = adjacent_mask_iou_pairs(masks_in_order, depths, cameras, occlusion_tol=occlusion_tol)
    return mean_or_none(v for p in pairs for v in p["ious"].values())
