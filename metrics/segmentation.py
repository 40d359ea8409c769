"""Mask metrics: IoU, the Boundary IoU band, Boundary IoU (docs/metrics.md).

Masks are 2-D arrays or tensors; non-bool input counts non-zero as foreground.

Empty unions are defined, never 0/0: `iou` and `boundary_iou` return `empty` when both masks
(or both bands) are empty. The default `empty=1.0` (two masks that agree there is nothing agree
perfectly). Each protocol passes its own rule, stated with the reference's code in its module:
`ovs3d.EMPTY_UNION_IOU` = 0 (the 3D-OVS reference, scikit-learn's `jaccard_score` with its default
`zero_division`) and `lerf.EMPTY_UNION_IOU` = 1 (LangSplat's evaluation divides 0 by 0 there).

Boundary band (Boundary IoU reference recipe, Cheng et al. 2021):
  d = max(1, round(ratio * sqrt(H^2 + W^2)))            (Python round, ratio 0.02 default)
  band(M) = M minus erode(zero-pad-1(M), 3x3 ones, d iterations) cropped back
i.e. the mask pixels within Chebyshev distance d of a background pixel or of the image border
(the border counts as background one pixel outside the image).
"""
from __future__ import annotations

import math
from typing import Any, Iterable

import cv2
import numpy as np

from gsbench.errors import InputError

from ._common import as_mask, mean_or_none, same_shape

BOUNDARY_DILATION_RATIO = 0.02
IOU_IMPL = "iou/v1"
BIOU_IMPL = "boundary-iou/ref-recipe/ratio0.02/v1"


def iou(pred: Any, gt: Any, *, empty: float = 1.0) -> float:
    """|P & G| / |P | G|; `empty` when the union is empty. Symmetric in its arguments."""
    p = as_mask(pred, "pred mask")
    g = as_mask(gt, "gt mask")
    same_shape(p, g, "pred mask", "gt mask")
    union = int(np.count_nonzero(p | g))
    if union == 0:
        return float(empty)
    return int(np.count_nonzero(p & g)) / union


def boundary_width(height: int, width: int, dilation_ratio: float = BOUNDARY_DILATION_RATIO) -> int:
    """d = max(1, round(ratio * image diagonal)) pixels."""
    if dilation_ratio < 0 or not math.isfinite(dilation_ratio):
        raise InputError(f"dilation_ratio must be a finite number >= 0, got {dilation_ratio}")
    return max(1, int(round(dilation_ratio * math.sqrt(height ** 2 + width ** 2))))


def boundary_band(mask: Any, *, dilation_ratio: float = BOUNDARY_DILATION_RATIO,
                  width: int | None = None) -> np.ndarray:
    """Boolean band of mask pixels within `width` (default from the ratio) of the background or border."""
    m = as_mask(mask, "mask")
    h, w = m.shape
    d = boundary_width(h, w, dilation_ratio) if width is None else int(width)
    if d < 1:
        raise ValueError(f"boundary width must be >= 1, got {d}")
    padded = cv2.copyMakeBorder(m.astype(np.uint8), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    # cv2.erode's default border value is "+inf" for erosion: outside the padded image never
    # erodes, so the zero pad ring is exactly the image border of the recipe.
    eroded = cv2.erode(padded, np.ones((3, 3), np.uint8), iterations=d)[1:h + 1, 1:w + 1]
    return m & (eroded == 0)


def boundary_iou(pred: Any, gt: Any, *, dilation_ratio: float = BOUNDARY_DILATION_RATIO,
                 empty: float = 1.0, coco_min: bool = False) -> float:
    """|B(G) & B(P)| / |B(G) | B(P)|; `empty` for an empty band union.

    coco_min=True returns min(IoU, BIoU) (the COCO Boundary-IoU variant); default off.
    """
    p = as_mask(pred, "pred mask")
    g = as_mask(gt, "gt mask")
    same_shape(p, g, "pred mask", "gt mask")
    bp = boundary_band(p, dilation_ratio=dilation_ratio)
    bg = boundary_band(g, dilation_ratio=dilation_ratio)
    union = int(np.count_nonzero(bp | bg))
    b = float(empty) if union == 0 else int(np.count_nonzero(bp & bg)) / union
    if coco_min:
        return min(b, iou(p, g, empty=empty))
    return b


def miou(values: Iterable[float]) -> float | None:
    """Plain mean of per-(frame, query) or per-(view, class) IoUs; None when there are none."""
    return mean_or_none(values)


def mbiou(values: Iterable[float]) -> float | None:
    """Mean Boundary IoU, averaged exactly like the mIoU it accompanies."""
    return mean_or_none(values)
