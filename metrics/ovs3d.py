"""3D-OVS evaluation (EVAL_PROTOCOLS.md, "3D-OVS").

Prediction: per pixel, argmax over the scene's classes of cos(feature, text_c); no background
class, no threshold (`ovs3d_predict`). GT: one binary mask per class (foreground where the PNG
is 255), resized NEAREST (cv2.INTER_NEAREST) to the evaluation resolution.

Per (view, class): IoU = |P_c & G_c| / |P_c | G_c| with 0 when the union is empty (the
reference's rule), and Boundary IoU with the same empty rule. A class without a GT mask in a
view counts as an empty GT mask (every scene class is scored in every view).
mIoU / mBIoU = plain mean over views x classes.
Pixel accuracy of a view = pixels whose predicted class has GT there / pixels covered by any GT
mask (pixels outside every GT mask are not scored: the protocol has no background class);
the scene value is the mean over views (views without any GT pixel are listed in `skipped`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import cv2
import numpy as np

from gsbench.errors import InputError

from ._common import as_mask, finite_float, mean_or_none, pixel_text_cosines, to_numpy
from .segmentation import BOUNDARY_DILATION_RATIO, boundary_iou, iou

OVS3D_IMPL = "3dovs/argmax-cos/v1"
MISSING_POLICIES = ("error", "skip", "zero")


def ovs3d_predict(pixel_features: Any, class_embeddings: Any) -> np.ndarray:
    """(H, W, D) features, (C, D) class text embeddings -> (H, W) int32 class index (first on ties)."""
    t = finite_float(class_embeddings, "class_embeddings")
    if t.ndim != 2 or t.shape[0] == 0:
        raise InputError(f"ovs3d_predict: expected class embeddings (C>0, D), got {t.shape}")
    cos, (h, w) = pixel_text_cosines(pixel_features, t, "pixel_features")
    return np.argmax(cos, axis=1).astype(np.int32).reshape(h, w)


def resize_nearest(mask: Any, width: int, height: int) -> np.ndarray:
    """A GT mask at the evaluation resolution (cv2.INTER_NEAREST)."""
    m = as_mask(mask, "gt mask")
    if m.shape == (height, width):
        return m
    return cv2.resize(m.astype(np.uint8), (int(width), int(height)), interpolation=cv2.INTER_NEAREST) > 0


def ovs3d_view_metrics(pred_labels: Any, gt_masks: Mapping[str, Any], class_names: Sequence[str], *,
                       dilation_ratio: float = BOUNDARY_DILATION_RATIO) -> dict:
    """Per-class IoU / BIoU and pixel accuracy of one view.

    pred_labels: (H, W) class indices into `class_names`; gt_masks: class name -> mask (any
    resolution, resized NEAREST to H x W); classes absent from the dict have an empty GT.
    Returns {"iou": {class: v}, "biou": {class: v}, "pixel_acc": float | None, "gt_pixels": int}.
    """
    pred = to_numpy(pred_labels, "pred_labels")
    if pred.ndim != 2 or not np.issubdtype(pred.dtype, np.integer):
        raise InputError(f"pred_labels: expected an integer (H, W) map, got {pred.dtype} {pred.shape}")
    n = len(class_names)
    if n == 0:
        raise InputError("class_names: empty")
    if pred.size and (pred.min() < 0 or pred.max() >= n):
        raise InputError(f"pred_labels: values must lie in [0, {n - 1}], got [{pred.min()}, {pred.max()}]")
    unknown = set(gt_masks) - set(class_names)
    if unknown:
        raise InputError(f"gt_masks: classes not in class_names: {sorted(unknown)}")
    h, w = pred.shape
    ious, bious = {}, {}
    correct = np.zeros((h, w), dtype=bool)
    covered = np.zeros((h, w), dtype=bool)
    for c, name in enumerate(class_names):
        g = resize_nearest(gt_masks[name], w, h) if name in gt_masks else np.zeros((h, w), bool)
        p = pred == c
        ious[name] = iou(p, g, empty=0.0)
        bious[name] = boundary_iou(p, g, dilation_ratio=dilation_ratio, empty=0.0)
        correct |= p & g
        covered |= g
    n_cov = int(covered.sum())
    acc = int(correct.sum()) / n_cov if n_cov else None
    return {"iou": ious, "biou": bious, "pixel_acc": acc, "gt_pixels": n_cov}


@dataclass
class Ovs3dView:
    """One test view: pred_labels None when the method produced no prediction."""

    name: str
    pred_labels: Any | None
    gt_masks: Mapping[str, Any]


@dataclass
class Ovs3dSceneResult:
    miou: float | None
    mbiou: float | None
    pixel_acc: float | None
    per_view: list[dict]       # {view, miou, mbiou, pixel_acc, iou: {class: v}, biou: {class: v}}
    skipped: list[dict]        # {view, reason}
    n_views: int
    missing: str
    impl: str = OVS3D_IMPL
    params: dict = field(default_factory=dict)


def evaluate_ovs3d_scene(views: Sequence[Ovs3dView], class_names: Sequence[str], *, missing: str = "error",
                         dilation_ratio: float = BOUNDARY_DILATION_RATIO) -> Ovs3dSceneResult:
    """The whole per-scene 3D-OVS protocol.

    missing: a view without a prediction raises ("error", default), is left out and listed in
    `skipped` ("skip"), or scores 0 for every class and pixel accuracy 0 and is listed ("zero").
    """
    if missing not in MISSING_POLICIES:
        raise InputError(f"missing must be one of {MISSING_POLICIES}, got {missing!r}")
    all_iou: list[float] = []
    all_biou: list[float] = []
    accs: list[float] = []
    per_view: list[dict] = []
    skipped: list[dict] = []
    for v in views:
        if v.pred_labels is None:
            if missing == "error":
                raise InputError(f"3D-OVS view {v.name!r}: no prediction for a GT view (missing='error')")
            if missing == "skip":
                skipped.append({"view": v.name, "reason": "missing prediction"})
                continue
            skipped.append({"view": v.name, "reason": "missing prediction, scored 0"})
            zeros = {c: 0.0 for c in class_names}
            m = {"iou": zeros, "biou": dict(zeros), "pixel_acc": 0.0}
        else:
            m = ovs3d_view_metrics(v.pred_labels, v.gt_masks, class_names, dilation_ratio=dilation_ratio)
        vi = [m["iou"][c] for c in class_names]
        vb = [m["biou"][c] for c in class_names]
        all_iou.extend(vi)
        all_biou.extend(vb)
        if m["pixel_acc"] is None:
            skipped.append({"view": v.name, "reason": "no GT pixel in any class: pixel accuracy undefined"})
        else:
            accs.append(m["pixel_acc"])
        per_view.append({"view": v.name, "miou": mean_or_none(vi), "mbiou": mean_or_none(vb),
                         "pixel_acc": m["pixel_acc"], "iou": m["iou"], "biou": m["biou"]})
    return Ovs3dSceneResult(miou=mean_or_none(all_iou), mbiou=mean_or_none(all_biou),
                            pixel_acc=mean_or_none(accs), per_view=per_view, skipped=skipped,
                            n_views=len(views), missing=missing,
                            params={"dilation_ratio": dilation_ratio, "empty_union": 0.0,
                                    "gt_resize": "nearest"})
