"""3D point-level scoring: classes of Gaussians, classes of labelled points, point mIoU / mAcc (docs/metrics.md).

The protocol that OpenGaussian, Dr. Splat and SceneSplat-Bench score in 3D, in three pure steps:

1. `gaussian_classes`: each Gaussian's class is the argmax of the cosine similarity between its
   feature (decoded the way the method answers a query) and the class text features. A Gaussian whose
   opacity is below the floor (strictly), or whose feature has zero norm, gets no class (-1).
   Ties between classes go to the lowest class index.
2. `point_classes`: each ground-truth point takes a class from the classed Gaussians (class >= 0):
   "nearest": the class of the nearest classed Gaussian by Euclidean distance of the centres; a point
              exactly equidistant from several takes the lowest class among them.
   "radius":  the majority class of the classed Gaussians whose centres lie within `radius`
              (distance <= radius); a tied vote goes to the lowest class index; a point with no
              classed Gaussian within the radius gets no class (-1).
   Without any classed Gaussian every point gets -1.
3. `point_miou_macc`: per class c present in the ground truth,
   IoU_c = TP_c / (TP_c + FP_c + FN_c) and Acc_c = TP_c / (number of GT points of class c);
   mIoU and mAcc are the plain means over the classes present in the ground truth. A point predicted
   -1 (no class) is wrong: an FN for its GT class and an FP for no class. A GT label of -1 marks an
   unlabelled point, left out of every count. A predicted class absent from the ground truth adds FPs
   only to that class, which is not averaged.

Bad input (a shape mismatch, NaN or inf, an out-of-range class or opacity) raises
`gsbench.errors.InputError` (a ValueError) with a message that names the argument.
The `3d-points` protocol (gsbench/evaluation/points3d_protocol.py) wires it into `gsbench eval`.
"""
from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, field
from typing import Any, Iterator

import numpy as np
from scipy.spatial import cKDTree

from gsbench.errors import InputError

from ._common import finite_float, mean_or_none, same_shape, to_numpy, unit_rows

POINTS3D_IMPL = {"nearest": "3d-points/argmax-cos/nearest/v1",
                 "radius": "3d-points/argmax-cos/radius-majority/v1"}
POINT_MODES = ("nearest", "radius")
ZERO_NORM = 1e-12        # a feature with an L2 norm at or below this has no direction, hence no class
_ROWS_PER_BLOCK = 65536  # Gaussians per matrix product (bounds the float32 temporaries)


@dataclass(frozen=True)
class PointScores:
    """Point-level scores of one scene (`point_miou_macc`).

    miou, macc: means over the classes present in the ground truth; None when no point is labelled.
    iou, acc: class index -> value, for the classes present in the ground truth.
    present: those classes, in increasing order.
    n_points: labelled points scored; n_unclassified: those among them predicted -1.
    """

    miou: float | None
    macc: float | None
    iou: dict[int, float] = field(default_factory=dict)
    acc: dict[int, float] = field(default_factory=dict)
    present: tuple[int, ...] = ()
    n_points: int = 0
    n_unclassified: int = 0


def gaussian_classes(features: Any, text_features: Any, opacity: Any, opacity_floor: float) -> np.ndarray:
    """Class of every Gaussian: argmax of cosine similarity to the class text features.

    Parameters
    ----------
    features : array_like or torch.Tensor, shape (N, D)
        Each Gaussian's feature, already decoded into the text-embedding space the way the method
        answers a query.
    text_features : array_like or torch.Tensor, shape (C, D)
        One text embedding per class, C > 0; none may have zero norm.
    opacity : array_like or torch.Tensor, shape (N,) or (N, 1)
        Each Gaussian's activated opacity, in [0, 1] (not the logit).
    opacity_floor : float
        Gaussians with opacity strictly below it get no class (OpenGaussian ignores them).

    Returns
    -------
    classes : ndarray of int64, shape (N,)
        Class index in [0, C), or -1 for a Gaussian below the opacity floor or with a zero-norm
        feature. Ties between classes go to the lowest index.

    Raises
    ------
    InputError
        On a shape mismatch, NaN or inf, a zero-norm text feature, or an opacity outside [0, 1].
    """
    f = finite_float(features, "features", np.float32)
    t = finite_float(text_features, "text_features")
    if f.ndim != 2:
        raise InputError(f"features: expected (N, D), got shape {f.shape}")
    op = _opacity(opacity, f.shape[0])
    if t.ndim != 2 or t.shape[0] == 0 or t.shape[1] != f.shape[1]:
        raise InputError(f"text_features: expected (C > 0, {f.shape[1]}) to match features {f.shape}, "
                         f"got {t.shape}")
    floor = float(opacity_floor)
    if not math.isfinite(floor):
        raise InputError(f"opacity_floor: must be a finite number, got {opacity_floor!r}")
    tu = unit_rows(t, "text_features", zero="error").astype(np.float32)
    out = np.full(f.shape[0], -1, dtype=np.int64)
    for start in range(0, f.shape[0], _ROWS_PER_BLOCK):
        block = f[start:start + _ROWS_PER_BLOCK]
        # argmax of f.t/|t| equals argmax of the cosine when |f| > 0; zero features are dropped below
        out[start:start + block.shape[0]] = np.argmax(block @ tu.T, axis=1)
    norms = np.sqrt(np.einsum("ij,ij->i", f, f, dtype=np.float64))
    out[(norms <= ZERO_NORM) | (op < floor)] = -1
    return out


def _opacity(opacity: Any, n: int) -> np.ndarray:
    """(N,) or (N, 1) activated opacity -> finite float64 (N,) in [0, 1]."""
    op = finite_float(opacity, "opacity")
    if op.ndim == 2 and op.shape[1] == 1:
        op = op[:, 0]
    if op.ndim != 1 or op.shape[0] != n:
        raise InputError(f"opacity: expected shape ({n},) to match the features, got {op.shape}")
    if op.size and (op.min() < 0.0 or op.max() > 1.0):
        raise InputError(f"opacity: expected activated values in [0, 1] (not logits), got "
                         f"[{op.min():.4g}, {op.max():.4g}]")
    return op


@contextlib.contextmanager
def _denormals_kept() -> Iterator[None]:
    """Denormal flushing off for the k-d tree, restored after. `import gsbench` turns flushing on for the
    render (gsbench/__init__.py); with it on, scipy 1.17's cKDTree crashed the process (SIGSEGV) while
    building a tree of 20,000 points of which 12,000 share the coordinate z = 0 exactly (a floor)."""
    import torch  # lazy: only to read and set the thread's flag (a core dependency)
    flushing = float((np.array([1e-310]) * np.float64(1.0))[0]) == 0.0
    if flushing:
        torch.set_flush_denormal(False)
    try:
        yield
    finally:
        if flushing:
            torch.set_flush_denormal(True)


def point_classes(points: Any, gaussian_means: Any, gaussian_class: Any, mode: str = "nearest",
                  radius: float | None = None) -> np.ndarray:
    """Class of every ground-truth point, taken from the classed Gaussians around it.

    Parameters
    ----------
    points : array_like or torch.Tensor, shape (P, 3)
        The labelled surface points.
    gaussian_means : array_like or torch.Tensor, shape (N, 3)
        The Gaussians' centres.
    gaussian_class : array_like or torch.Tensor of int, shape (N,)
        Each Gaussian's class (`gaussian_classes`); -1 means no class, and such Gaussians are ignored.
    mode : {"nearest", "radius"}
        "nearest": the class of the nearest classed Gaussian (Euclidean distance between centres);
        a point exactly equidistant from classed Gaussians of different classes takes the lowest class.
        "radius": the majority class among the classed Gaussians at distance <= `radius`; a tied
        vote goes to the lowest class index; a point with none within the radius gets -1.
    radius : float, optional
        The neighbourhood radius, > 0, required by "radius" and not accepted by "nearest".

    Returns
    -------
    classes : ndarray of int64, shape (P,)
        Class index, or -1 (no classed Gaussian at all, or none within the radius).

    Raises
    ------
    InputError
        On a shape mismatch, NaN or inf, a class below -1, an unknown mode or a bad radius.
    """
    p, means, cls = _point_inputs(points, gaussian_means, gaussian_class)
    if mode not in POINT_MODES:
        raise InputError(f"mode: must be one of {POINT_MODES}, got {mode!r}")
    if mode == "nearest" and radius is not None:
        raise InputError("radius: only the 'radius' mode takes a radius; pass radius=None with mode='nearest'")
    if mode == "radius" and (radius is None or not math.isfinite(float(radius)) or float(radius) <= 0):
        raise InputError(f"radius: mode 'radius' needs a finite radius > 0, got {radius!r}")
    keep = cls >= 0
    out = np.full(p.shape[0], -1, dtype=np.int64)
    if p.shape[0] == 0 or not np.any(keep):
        return out
    means, cls = means[keep], cls[keep]
    with _denormals_kept():
        tree = cKDTree(means)
        if mode == "nearest":
            return _nearest(tree, p, means, cls)
        rows, idx = _pairs(tree.query_ball_point(p, r=float(radius)))
    if rows.size == 0:
        return out
    votes = np.zeros((p.shape[0], int(cls.max()) + 1), dtype=np.int64)
    np.add.at(votes, (rows, cls[idx]), 1)
    has = votes.sum(axis=1) > 0
    out[has] = np.argmax(votes[has], axis=1)   # argmax: the first (lowest) class on a tied vote
    return out


def _point_inputs(points: Any, gaussian_means: Any, gaussian_class: Any
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Checked (P, 3) points, (N, 3) centres and (N,) int64 classes."""
    p = finite_float(points, "points")
    means = finite_float(gaussian_means, "gaussian_means")
    cls = to_numpy(gaussian_class, "gaussian_class")
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"points: expected (P, 3), got shape {p.shape}")
    if means.ndim != 2 or means.shape[1] != 3:
        raise InputError(f"gaussian_means: expected (N, 3), got shape {means.shape}")
    if cls.shape != (means.shape[0],):
        raise InputError(f"gaussian_class: expected shape ({means.shape[0]},) to match gaussian_means, "
                         f"got {cls.shape}")
    if cls.size and not np.issubdtype(cls.dtype, np.integer):
        raise InputError(f"gaussian_class: expected integer classes, got dtype {cls.dtype}")
    cls = cls.astype(np.int64)
    if cls.size and cls.min() < -1:
        raise InputError(f"gaussian_class: classes must be >= -1 (-1 = no class), got {cls.min()}")
    return p, means, cls


def _pairs(lists: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cKDTree neighbour lists (one per point) -> flat (point row, Gaussian index) pairs."""
    lengths = np.fromiter((len(a) for a in lists), dtype=np.int64, count=len(lists))
    rows = np.repeat(np.arange(len(lists), dtype=np.int64), lengths)
    idx = np.fromiter((j for a in lists for j in a), dtype=np.int64, count=int(lengths.sum()))
    return rows, idx


def _nearest(tree: cKDTree, p: np.ndarray, means: np.ndarray, cls: np.ndarray) -> np.ndarray:
    """The class of each point's nearest Gaussian; the lowest class among exactly equidistant ones."""
    d0, nearest = tree.query(p, k=1)
    out = cls[nearest].astype(np.int64)
    # Candidates a hair beyond the nearest distance, then exact squared distances decide the ties
    # (the tree's own pick among equidistant Gaussians is not specified).
    rows, idx = _pairs(tree.query_ball_point(p, r=d0 * (1.0 + 1e-9) + 1e-12))
    if rows.size == 0:
        return out
    dist2 = np.sum((p[rows] - means[idx]) ** 2, axis=1)
    best = np.full(p.shape[0], np.inf)
    np.minimum.at(best, rows, dist2)
    tied = dist2 == best[rows]
    low = np.full(p.shape[0], np.iinfo(np.int64).max, dtype=np.int64)
    np.minimum.at(low, rows[tied], cls[idx[tied]])
    found = low != np.iinfo(np.int64).max
    out[found] = low[found]
    return out


def point_miou_macc(pred: Any, gt: Any, num_classes: int) -> PointScores:
    """Point mIoU and mAcc over the classes present in the ground truth.

    Parameters
    ----------
    pred : array_like or torch.Tensor of int, shape (P,)
        Predicted class per point in [0, num_classes), or -1 for no class (always wrong).
    gt : array_like or torch.Tensor of int, shape (P,)
        Ground-truth class per point in [0, num_classes), or -1 for an unlabelled point (not scored).
    num_classes : int
        The number of classes C > 0.

    Returns
    -------
    PointScores
        For each class c present in `gt`: IoU_c = TP_c / (TP_c + FP_c + FN_c) and
        Acc_c = TP_c / |{points with gt == c}|; miou and macc are their plain means (None when no
        point is labelled).

    Raises
    ------
    InputError
        On a shape mismatch, non-integer labels, or a label outside [-1, num_classes).
    """
    c = int(num_classes)
    if c <= 0:
        raise InputError(f"num_classes: must be > 0, got {num_classes!r}")
    pr = _labels(pred, "pred", c)
    g = _labels(gt, "gt", c)
    same_shape(pr, g, "pred", "gt")
    scored = g >= 0
    pr, g = pr[scored], g[scored]
    gt_count = np.bincount(g, minlength=c)
    pred_count = np.bincount(pr[pr >= 0], minlength=c)
    tp = np.bincount(g[pr == g], minlength=c)
    present = tuple(int(k) for k in np.flatnonzero(gt_count > 0))
    iou, acc = {}, {}
    for k in present:
        union = int(gt_count[k] + pred_count[k] - tp[k])   # TP + FP + FN
        iou[k] = float(tp[k]) / union if union > 0 else 0.0
        acc[k] = float(tp[k]) / float(gt_count[k]) if gt_count[k] > 0 else 0.0
    return PointScores(miou=mean_or_none(iou.values()), macc=mean_or_none(acc.values()), iou=iou, acc=acc,
                       present=present, n_points=int(g.size), n_unclassified=int(np.count_nonzero(pr < 0)))


def _labels(x: Any, name: str, num_classes: int) -> np.ndarray:
    """A 1-D integer label array with values in [-1, num_classes)."""
    a = to_numpy(x, name)
    if a.ndim != 1:
        raise InputError(f"{name}: expected a 1-D array of class indices, got shape {a.shape}")
    if a.size and not np.issubdtype(a.dtype, np.integer):
        raise InputError(f"{name}: expected integer class indices, got dtype {a.dtype}")
    a = a.astype(np.int64)
    if a.size and (a.min() < -1 or a.max() >= num_classes):
        raise InputError(f"{name}: class indices must lie in [-1, {num_classes - 1}], "
                         f"got [{a.min()}, {a.max()}]")
    return a
