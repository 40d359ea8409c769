"""Rendered-depth error against the scene's GT depth on the held-out views (synthetic scenes).

Why: the depth controls need to see whether L_depth moves the geometry, not only the colours, and
to tell a wrong depth from a missing surface. Three numbers, each the mean over the held-out views
of a per-view value, with z the GT depth resized by nearest neighbour to the evaluation size and
only pixels with a GT depth counted:
- depth_absrel: mean |D - z| / z, D the rendered alpha-composited depth (sum of T alpha z). A pixel
  the render leaves empty has D = 0 and counts as 1, so on views the training views barely see it
  mostly measures coverage.
- depth_coverage: the share of pixels whose accumulated alpha exceeds COVERED_ALPHA.
- depth_absrel_covered: mean |D / alpha - z| / z over those covered pixels: the depth of the covered
  part of the pixel (what L_depth compares with the prior), so a half-transparent but correctly
  placed surface is not counted as near.
"""
from __future__ import annotations

import numpy as np

from gsbench.metric_table import DEPTH_METRICS
from gsbench.resize import resize_nearest

from .block import Block, to_numpy
from .frames import view_name

DEPTH_IMPL = "absrel-composited-depth-vs-gt-z-v1"
COVERED_ALPHA = 0.5   # a pixel is covered when its accumulated alpha (1 - final transmittance) exceeds this
COVERED_IMPL = "absrel-expected-depth-on-alpha-gt-0.5-vs-gt-z-v1"
COVERAGE_IMPL = "share-of-gt-depth-pixels-with-alpha-gt-0.5-v1"
NEAR = 1e-6   # GT depth at or below this is "no depth"


def _gt_pixels(z: np.ndarray, *others: np.ndarray) -> np.ndarray:
    """Pixels with a finite GT depth above NEAR and finite values in every other map."""
    ok = np.isfinite(z) & (z > NEAR)
    for o in others:
        ok &= np.isfinite(o)
    return ok


def depth_absrel(pred: np.ndarray, gt: np.ndarray) -> float | None:
    """Mean |pred - gt| / gt over the pixels with a finite GT depth above NEAR; None when there is none."""
    p, z = np.asarray(pred, dtype=np.float64), np.asarray(gt, dtype=np.float64)
    ok = _gt_pixels(z, p)
    if not ok.any():
        return None
    return float(np.mean(np.abs(p[ok] - z[ok]) / z[ok]))


def depth_covered(pred: np.ndarray, alpha: np.ndarray, gt: np.ndarray,
                  threshold: float = COVERED_ALPHA) -> tuple[float | None, float | None]:
    """(mean |pred / alpha - gt| / gt over the GT-depth pixels with alpha > threshold, the share of
    GT-depth pixels with alpha > threshold). The error is None when no pixel is covered, both are
    None when no pixel has a GT depth. `threshold` must lie in (0, 1), which also guards pred / alpha."""
    if not 0.0 < float(threshold) < 1.0:
        raise ValueError(f"the covered-alpha threshold must lie in (0, 1), got {threshold}")
    p, a, z = (np.asarray(x, dtype=np.float64) for x in (pred, alpha, gt))
    ok = _gt_pixels(z, p, a)
    n = int(ok.sum())
    if n == 0:
        return None, None
    covered = ok & (a > threshold)
    share = float(covered.sum()) / n
    if not covered.any():
        return None, share
    d = p[covered] / a[covered]
    return float(np.mean(np.abs(d - z[covered]) / z[covered])), share


def depth_metrics(method, scene, ids: list[int], cams: list) -> Block:
    """depth_absrel, depth_absrel_covered and depth_coverage on the held-out views (skipped with the
    reason when the scene has no GT depth or nothing is held out)."""
    out = Block()
    if not getattr(scene, "has_depth", False):
        out.skip(DEPTH_METRICS, "scene has no GT depth")
        return out
    if not ids:
        out.skip(DEPTH_METRICS, "no held-out view (train.holdout: none trains on every view)")
        return out
    names = [view_name(scene, i) for i in ids]
    absrel, covered, coverage = [], [], []
    for i, cam in zip(ids, cams):
        r = method.render(cam)
        d, a = to_numpy(r.depth), to_numpy(r.alpha)
        z = resize_nearest(np.asarray(scene.gt_depth(i), dtype=np.float32), cam.width, cam.height)
        absrel.append(depth_absrel(d, z))
        err, share = depth_covered(d, a, z)
        covered.append(err)
        coverage.append(share)
    out.put_mean("depth_absrel", absrel, DEPTH_IMPL, names)
    out.put_mean("depth_absrel_covered", covered, COVERED_IMPL, names)
    out.put_mean("depth_coverage", coverage, COVERAGE_IMPL, names)
    return out
