"""Ordering metrics for the pseudo-video (docs/priors.md, "Ordering and its metrics").

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

`adjacent_mask_iou_strict`: the same warp, but every id seen in the covered region of either
frame is scored (ids in one frame only score 0). A track that ends and a new track that starts
for the same object both count as misses, so re-labelling an object between frames is not free.

`adjacent_mask_iou_flow`: the strict score for scenes without GT depth: frame t's ids are carried
into t+1 by backward lookup through Farneback optical flow (OpenCV), an estimator other than the
DIS flow the weight-free propagator uses, so the metric does not grade the propagator with its
own warp; pixels failing the forward-backward check (|B(p) + F(p + B(p))|^2 < 0.01 (|B|^2 +
|F|^2) + 0.5 px^2) are uncovered.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from gsbench.errors import InputError

from ._common import finite_float, mean_or_none, to_numpy

ORDERING_DISTANCE_IMPL = "ordering/adjacent-centre-distance/v1"
ORDERING_MASK_IOU_IMPL = "ordering/adjacent-mask-iou/zbuffer-splat/v1"
ORDERING_MASK_IOU_STRICT_IMPL = "ordering/adjacent-mask-iou-strict/zbuffer-splat/v1"
ORDERING_MASK_IOU_FLOW_IMPL = "ordering/adjacent-mask-iou-strict/farneback-fb/v1"
FB_ALPHA = 0.01
FB_BETA = 0.5


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


def _score_pair(warped: np.ndarray, covered: np.ndarray, ma: np.ndarray, mb: np.ndarray, strict: bool
                ) -> tuple[dict[int, float], int]:
    if strict:
        ids = sorted(set(np.unique(warped[covered & (warped >= 0)]).tolist())
                     | set(np.unique(mb[covered & (mb >= 0)]).tolist()))
    else:
        ids = sorted(set(np.unique(ma[ma >= 0]).tolist()) & set(np.unique(mb[mb >= 0]).tolist()))
    ious: dict[int, float] = {}
    excluded = 0
    for k in ids:
        wk = warped == k
        mk = (mb == k) & covered
        union = int(np.count_nonzero(wk | mk))
        if union == 0:
            excluded += 1
            continue
        ious[int(k)] = int(np.count_nonzero(wk & mk)) / union
    return ious, excluded


def _check_masks(masks_in_order: Sequence[Any]) -> list[np.ndarray]:
    out = []
    for t, x in enumerate(masks_in_order):
        m = to_numpy(x, f"masks[{t}]")
        if m.ndim != 2 or not np.issubdtype(m.dtype, np.integer):
            raise InputError(f"masks[{t}]: expected an integer (H, W) track-id map, got {m.dtype} {m.shape}")
        out.append(m.astype(np.int64))
    return out


def adjacent_mask_iou_pairs(masks_in_order: Sequence[Any], depths: Sequence[Any], cameras: Sequence[Any], *,
                            occlusion_tol: float = 0.05, strict: bool = False) -> list[dict]:
    """Per neighbouring pair: {"pair": (t, t+1), "ious": {track id: IoU}, "n_excluded": int}.

    strict=False scores ids present in both frames; strict=True every id seen in either frame.
    """
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
        ious, excluded = _score_pair(warped, covered, ma, mb, strict)
        out.append({"pair": (t, t + 1), "ious": ious, "n_excluded": excluded,
                    "covered_fraction": float(covered.mean())})
    return out


def adjacent_mask_iou(masks_in_order: Sequence[Any], depths: Sequence[Any], cameras: Sequence[Any], *,
                      occlusion_tol: float = 0.05) -> float | None:
    """Mean IoU of shared track ids between neighbouring frames after depth warping (see module doc)."""
    pairs = adjacent_mask_iou_pairs(masks_in_order, depths, cameras, occlusion_tol=occlusion_tol)
    return mean_or_none(v for p in pairs for v in p["ious"].values())


def adjacent_mask_iou_strict(masks_in_order: Sequence[Any], depths: Sequence[Any], cameras: Sequence[Any], *,
                             occlusion_tol: float = 0.05) -> float | None:
    """Mean IoU over every id seen in either neighbouring frame (new tracks count as misses)."""
    pairs = adjacent_mask_iou_pairs(masks_in_order, depths, cameras, occlusion_tol=occlusion_tol, strict=True)
    return mean_or_none(v for p in pairs for v in p["ious"].values())


def _gray_u8(img: np.ndarray, name: str) -> np.ndarray:
    a = finite_float(img, name)
    if a.ndim == 3:
        a = a[..., :3].mean(axis=-1)
    if a.ndim != 2:
        raise InputError(f"{name}: expected an (H, W) or (H, W, C) image, got {a.shape}")
    return np.clip(np.rint(a * 255.0), 0, 255).astype(np.uint8)


def _farneback(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    import cv2
    return cv2.calcOpticalFlowFarneback(a, b, None, 0.5, 3, 9, 5, 5, 1.1, 0)


def flow_warp_ids(mask_a: np.ndarray, image_a: np.ndarray, image_b: np.ndarray) -> np.ndarray:
    """Frame a's ids carried into frame b through backward Farneback flow; -2 marks uncovered pixels."""
    import cv2
    F = _farneback(image_a, image_b)
    B = _farneback(image_b, image_a)
    H, W = mask_a.shape
    xs, ys = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    qx, qy = xs + B[..., 0], ys + B[..., 1]
    Fq = cv2.remap(F, qx, qy, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    err = ((B + Fq) ** 2).sum(-1)
    mag = (B ** 2).sum(-1) + (Fq ** 2).sum(-1)
    ix, iy = np.rint(qx).astype(np.int64), np.rint(qy).astype(np.int64)
    ok = (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H) & (err < FB_ALPHA * mag + FB_BETA)
    out = np.full((H, W), -2, dtype=np.int64)
    out[ok] = mask_a[iy[ok], ix[ok]]
    return out


def adjacent_mask_iou_flow_pairs(masks_in_order: Sequence[Any], images_in_order: Sequence[Any]) -> list[dict]:
    """Per neighbouring pair, the strict scores with a flow warp (see module doc)."""
    masks = _check_masks(masks_in_order)
    if len(images_in_order) != len(masks):
        raise InputError(f"adjacent_mask_iou_flow: {len(masks)} masks but {len(images_in_order)} images")
    grays = [_gray_u8(im, f"images[{t}]") for t, im in enumerate(images_in_order)]
    for t, (m, g) in enumerate(zip(masks, grays)):
        if m.shape != g.shape:
            raise InputError(f"images[{t}] has shape {g.shape} but masks[{t}] has {m.shape}")
    out = []
    for t in range(len(masks) - 1):
        warped = flow_warp_ids(masks[t], grays[t], grays[t + 1])
        covered = warped != -2
        ious, excluded = _score_pair(warped, covered, masks[t], masks[t + 1], True)
        out.append({"pair": (t, t + 1), "ious": ious, "n_excluded": excluded,
                    "covered_fraction": float(covered.mean())})
    return out


def adjacent_mask_iou_flow(masks_in_order: Sequence[Any], images_in_order: Sequence[Any]) -> float | None:
    """Strict adjacent mask IoU with a Farneback flow warp: for scenes without GT depth."""
    return mean_or_none(v for p in adjacent_mask_iou_flow_pairs(masks_in_order, images_in_order)
                        for v in p["ious"].values())
