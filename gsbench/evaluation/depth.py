"""Rendered-depth error against the scene's GT depth on the held-out views (synthetic scenes).

Why: the depth controls need to see whether L_depth moves the geometry, not only the colours.
depth_absrel = mean over views of the mean over pixels with GT depth of |D - z| / z, where D is the
rendered alpha-composited depth (sum of T alpha z, as the depth loss sees it) at the evaluation
size and z the GT depth resized by nearest neighbour. A pixel the render leaves empty has D = 0
and counts as a relative error of 1; nothing is thresholded.
"""
from __future__ import annotations

import numpy as np

from gsbench.metric_table import DEPTH_METRICS
from gsbench.resize import resize_nearest

from .block import Block, to_numpy
from .frames import view_name

DEPTH_IMPL = "absrel-composited-depth-vs-gt-z-v1"
NEAR = 1e-6   # GT depth at or below this is "no depth"


def depth_absrel(pred: np.ndarray, gt: np.ndarray) -> float | None:
    """Mean |pred - gt| / gt over the pixels with a finite GT depth above NEAR; None when there is none."""
    p, z = np.asarray(pred, dtype=np.float64), np.asarray(gt, dtype=np.float64)
    ok = np.isfinite(z) & (z > NEAR) & np.isfinite(p)
    if not ok.any():
        return None
    return float(np.mean(np.abs(p[ok] - z[ok]) / z[ok]))


def depth_metrics(method, scene, ids: list[int], cams: list) -> Block:
    """depth_absrel on the held-out views (skipped with the reason when the scene has no GT depth)."""
    out = Block()
    if not getattr(scene, "has_depth", False):
        out.skip(DEPTH_METRICS, "scene has no GT depth")
        return out
    if not ids:
        out.skip(DEPTH_METRICS, "no held-out view (train.holdout: none trains on every view)")
        return out
    names = [view_name(scene, i) for i in ids]
    vals = []
    for i, cam in zip(ids, cams):
        d = to_numpy(method.render(cam).depth)
        z = resize_nearest(np.asarray(scene.gt_depth(i), dtype=np.float32), cam.width, cam.height)
        vals.append(depth_absrel(d, z))
    out.put_mean("depth_absrel", vals, DEPTH_IMPL, names)
    return out
