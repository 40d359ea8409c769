"""3D-OVS evaluation (docs/protocols.md).

Prediction: per pixel, argmax over the scene's classes of cos(feature, text_c); no background
class, no threshold (`ovs3d_predict`). GT: one binary mask per class (foreground where the PNG
is 255), resized to the evaluation resolution by centre sampling (`resize_nearest`, as PIL NEAREST).

Per (view, class): IoU = |P_c & G_c| / |P_c | G_c|, and Boundary IoU, for every class of the scene
in every view. The empty-class rule (EMPTY_GT_RULE) is the reference's: the 3D-OVS code
(Kunhao-Liu/3D-OVS, renderer.py `evaluation_segmentation_test`) scores each view with scikit-learn's
`jaccard_score(gt, one_hot, average=None)` over all classes, whose default `zero_division` gives 0
(with a warning) when GT and prediction of a class are both empty, and averages every (view, class)
value with np.mean. So a class absent from a view's GT scores 0 whether or not the prediction marks
it; nothing is skipped. The reference's reader needs a mask file per class and view; gsbench counts a
class without a file as an empty GT. The pairs with an empty GT are listed per view (`empty_gt`,
and `empty_both` for those whose prediction is empty too), so such zeros are never hidden.
mIoU / mBIoU = plain mean over views x classes.
Pixel accuracy, two named rules (`pixel_accuracy`): "reference" (pixel_acc_3dovs), exact
one-hot match over all H x W pixels as the reference scores it; "labelled"
(pixel_acc_labelled_3dovs), gsbench's variant over GT-covered pixels. Scene value = mean over views.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from gsbench.errors import InputError
from gsbench.resize import resize_nearest

from ._common import as_mask, finite_float, mean_or_none, pixel_text_cosines, to_numpy
from .segmentation import BOUNDARY_DILATION_RATIO, boundary_iou, iou

OVS3D_IMPL = "3dovs/argmax-cos/v1"
MISSING_POLICIES = ("error", "skip", "zero")
EMPTY_UNION_IOU = 0.0   # IoU and BIoU of a class whose GT and prediction are both empty (the reference's)
EMPTY_GT_RULE = ("every class is scored in every view; an empty GT mask scores IoU 0, also when the prediction "
                 "is empty (the 3D-OVS reference: sklearn jaccard_score, zero_division 0)")


def ovs3d_predict(pixel_features: Any, class_embeddings: Any, *, pixel_norms: np.ndarray | None = None) -> np.ndarray:
    """(H, W, D) features, (C, D) class text embeddings -> (H, W) int32 class index (first on ties).
    pixel_norms: the features' `metrics._common.pixel_norms`, when already computed."""
    cos, (h, w) = pixel_text_cosines(pixel_features, class_texts(class_embeddings), "pixel_features", pixel_norms)
    return ovs3d_labels(cos, h, w)


def class_texts(class_embeddings: Any) -> np.ndarray:
    """The (C > 0, D) class text embeddings as a finite float64 array (InputError otherwise)."""
    t = finite_float(class_embeddings, "class_embeddings")
    if t.ndim != 2 or t.shape[0] == 0:
        raise InputError(f"ovs3d_predict: expected class embeddings (C>0, D), got {t.shape}")
    return t


def ovs3d_labels(cosines: np.ndarray, height: int, width: int) -> np.ndarray:
    """(H*W, C) pixel-class cosines -> (H, W) int32 class index (first on ties): `ovs3d_predict` from
    cosines computed elsewhere (evaluation computes them a block of pixels at a time)."""
    return np.argmax(cosines, axis=1).astype(np.int32).reshape(height, width)


PIXEL_ACC_RULES = ("reference", "labelled")
PIXEL_ACC_IMPL = {"reference": "pixel-acc/exact-match-all-pixels/3dovs-ref/v1",
                  "labelled": "pixel-acc/labelled-pixels-any-gt-class/gsbench/v1"}


def pixel_accuracy(pred_labels: np.ndarray, gt_stack: np.ndarray, rule: str) -> float | None:
    """Pixel accuracy of one view under a named rule (the one function both code paths use).

    pred_labels: (H, W) int, a class index or -1 for "no class"; gt_stack: (C, H, W) bool, one GT
    mask per class (masks may overlap or leave pixels unlabelled).
      "reference": the 3D-OVS reference (accuracy of one-hot rows): a pixel is right only when
                   its GT row equals the prediction's one-hot row, over all H x W pixels; an
                   unlabelled or doubly-labelled pixel is right only for the "no class" prediction
                   that matches it exactly.
      "labelled":  gsbench's variant: over pixels some GT mask covers, right when the predicted
                   class has GT there (overlaps count for either class); None without such pixels.
    """
    if rule not in PIXEL_ACC_RULES:
        raise InputError(f"pixel accuracy rule must be one of {PIXEL_ACC_RULES}, got {rule!r}")
    pred = np.asarray(pred_labels)
    gt = np.asarray(gt_stack, dtype=bool)
    if gt.ndim != 3 or gt.shape[1:] != pred.shape:
        raise InputError(f"pixel accuracy: GT stack {gt.shape} does not match predictions {pred.shape}")
    c = gt.shape[0]
    has = (pred >= 0) & (pred < c)
    idx = np.where(has, pred, 0)
    hit = has & np.take_along_axis(gt, idx[None].astype(np.intp), axis=0)[0]
    count = gt.sum(axis=0)
    if rule == "reference":
        right = (hit & (count == 1)) | (~has & (count == 0))
        return float(np.count_nonzero(right)) / float(pred.size) if pred.size else None
    covered = count > 0
    n = int(np.count_nonzero(covered))
    return float(np.count_nonzero(hit & covered)) / n if n else None


def ovs3d_view_metrics(pred_labels: Any, gt_masks: Mapping[str, Any], class_names: Sequence[str], *,
                       dilation_ratio: float = BOUNDARY_DILATION_RATIO) -> dict:
    """Per-class IoU / BIoU and pixel accuracy of one view.

    pred_labels: (H, W) class indices into `class_names`; gt_masks: class name -> mask (any
    resolution, resized NEAREST to H x W); classes absent from the dict have an empty GT.
    Returns {"iou": {class: v}, "biou": {class: v}, "pixel_acc": float | None, "gt_pixels": int,
    "empty_gt": [classes with an empty GT], "empty_both": [those whose prediction is empty too]}.
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
    ious, bious, empty_gt, empty_both = {}, {}, [], []
    stack = np.zeros((n, h, w), dtype=bool)
    for c, name in enumerate(class_names):
        if name in gt_masks:
            stack[c] = resize_nearest(as_mask(gt_masks[name], f"gt mask {name!r}"), w, h)
        p = pred == c
        ious[name] = iou(p, stack[c], empty=EMPTY_UNION_IOU)
        bious[name] = boundary_iou(p, stack[c], dilation_ratio=dilation_ratio, empty=EMPTY_UNION_IOU)
        if not stack[c].any():
            empty_gt.append(name)
            if not p.any():
                empty_both.append(name)
    return {"iou": ious, "biou": bious, "pixel_acc": pixel_accuracy(pred, stack, "reference"),
            "pixel_acc_labelled": pixel_accuracy(pred, stack, "labelled"),
            "gt_pixels": int(np.count_nonzero(stack.any(axis=0))), "empty_gt": empty_gt, "empty_both": empty_both}


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
    pixel_acc: float | None    # rule "reference"
    pixel_acc_labelled: float | None
    per_view: list[dict]       # {view, miou, mbiou, pixel_acc, iou: {class: v}, biou: {class: v}, empty_gt, empty_both}
    skipped: list[dict]        # {view, reason}
    n_views: int
    missing: str
    impl: str = OVS3D_IMPL
    params: dict = field(default_factory=dict)
    empty_both: int = 0        # (view, class) pairs with an empty GT and an empty prediction, each scored 0


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
    accs_lab: list[float] = []
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
            m = {"iou": zeros, "biou": dict(zeros), "pixel_acc": 0.0, "pixel_acc_labelled": 0.0,
                 "empty_gt": [], "empty_both": []}
        else:
            m = ovs3d_view_metrics(v.pred_labels, v.gt_masks, class_names, dilation_ratio=dilation_ratio)
        vi = [m["iou"][c] for c in class_names]
        vb = [m["biou"][c] for c in class_names]
        all_iou.extend(vi)
        all_biou.extend(vb)
        accs.append(m["pixel_acc"])
        if m["pixel_acc_labelled"] is None:
            skipped.append({"view": v.name, "reason": "no GT pixel in any class: labelled pixel accuracy undefined"})
        else:
            accs_lab.append(m["pixel_acc_labelled"])
        per_view.append({"view": v.name, "miou": mean_or_none(vi), "mbiou": mean_or_none(vb),
                         "pixel_acc": m["pixel_acc"], "pixel_acc_labelled": m["pixel_acc_labelled"],
                         "iou": m["iou"], "biou": m["biou"], "empty_gt": m["empty_gt"], "empty_both": m["empty_both"]})
    return Ovs3dSceneResult(miou=mean_or_none(all_iou), mbiou=mean_or_none(all_biou),
                            pixel_acc=mean_or_none(accs), pixel_acc_labelled=mean_or_none(accs_lab),
                            per_view=per_view, skipped=skipped,
                            n_views=len(views), missing=missing,
                            params={"dilation_ratio": dilation_ratio, "empty_union": EMPTY_UNION_IOU,
                                    "empty_gt_rule": EMPTY_GT_RULE, "gt_resize": "nearest-centre"},
                            empty_both=sum(len(v["empty_both"]) for v in per_view))


# ---------------------------------------------------------------------------- the protocol's forks
# The default fork ("3dovs-closed-set") is everything above: one class per pixel by the argmax over the
# scene's classes. The forks below give each class query its own mask, which may overlap or leave pixels
# unclassed, so they have no pixel accuracy; their IoU / BIoU follow the same empty-class rule.
THRESHOLD_IMPL = "3dovs/per-query-threshold-langsplat/v1"
DYNAMIC_IMPL = "3dovs/per-query-dynamic-threshold/v1"
DYNAMIC_STABILITY = 0.4       # least stability of an accepted threshold
DYNAMIC_AREA = (0.005, 0.9)   # least and largest share of the image an accepted mask covers
DYNAMIC_STEP = 0.05           # candidate thresholds 0.05, 0.10, ..., 0.95 of the normalised relevancy


def _normalised(relevancy: Any) -> np.ndarray:
    r = finite_float(relevancy, "relevancy")
    if r.ndim != 2:
        raise InputError(f"relevancy: expected (H, W), got shape {r.shape}")
    lo, hi = float(r.min()), float(r.max())
    return (r - lo) / (hi - lo + 1e-9)


def dynamic_threshold(relevancy: Any, *, stability: float = DYNAMIC_STABILITY,
                      area: tuple[float, float] = DYNAMIC_AREA, step: float = DYNAMIC_STEP) -> float | None:
    """The threshold the dynamic rule picks for one query's relevancy map (H, W), or None.

    x = min-max normalised relevancy. For each candidate t = step, 2 step, ... < 1: the mask x > t covers
    a share a(t) of the image, and its stability is s(t) = |x > t + step| / |x > t - step| (the IoU of
    the two nested masks around t; 0 when the wider one is empty). A candidate is accepted when
    s(t) >= stability and area[0] <= a(t) <= area[1]; the accepted t with the largest s(t) wins (the
    larger t on ties). None when no candidate is accepted: the query's mask is empty.
    """
    x = _normalised(relevancy)
    n = x.size
    best, best_s = None, -1.0
    k = 1
    while k * step < 1.0 - 1e-12:
        t = k * step
        share = float(np.count_nonzero(x > t)) / n if n else 0.0
        wide = int(np.count_nonzero(x > t - step))
        s = float(np.count_nonzero(x > t + step)) / wide if wide else 0.0
        if s >= stability and area[0] <= share <= area[1] and s >= best_s:
            best, best_s = t, s
        k += 1
    return best


def dynamic_threshold_mask(relevancy: Any, **rule: Any) -> np.ndarray:
    """One query's mask under the dynamic rule (`dynamic_threshold`); empty when no threshold is accepted."""
    x = _normalised(relevancy)
    t = dynamic_threshold(relevancy, **rule)
    return np.zeros(x.shape, bool) if t is None else x > t


def evaluate_ovs3d_masks(views: Sequence[Ovs3dView], class_names: Sequence[str], *, impl: str,
                         dilation_ratio: float = BOUNDARY_DILATION_RATIO) -> Ovs3dSceneResult:
    """The 3D-OVS scene scores of per-class masks: each view's `pred_labels` is a (C, H, W) bool stack
    (class k's mask, in class_names' order; masks may overlap), never None. IoU and BIoU per (view,
    class) with the reference's empty-class rule (0 when the GT is empty), plain means over views x
    classes; pixel accuracy is None (no single class per pixel)."""
    all_iou: list[float] = []
    all_biou: list[float] = []
    per_view: list[dict] = []
    for v in views:
        pred = np.asarray(v.pred_labels, dtype=bool)
        if pred.ndim != 3 or pred.shape[0] != len(class_names):
            raise InputError(f"3D-OVS view {v.name!r}: expected one mask per class, got shape {pred.shape}")
        h, w = pred.shape[1:]
        ious, bious, empty_gt, empty_both = {}, {}, [], []
        for c, name in enumerate(class_names):
            gt = (resize_nearest(as_mask(v.gt_masks[name], f"gt mask {name!r}"), w, h) if name in v.gt_masks
                  else np.zeros((h, w), bool))
            ious[name] = iou(pred[c], gt, empty=EMPTY_UNION_IOU)
            bious[name] = boundary_iou(pred[c], gt, dilation_ratio=dilation_ratio, empty=EMPTY_UNION_IOU)
            if not gt.any():
                empty_gt.append(name)
                if not pred[c].any():
                    empty_both.append(name)
        vi, vb = [ious[c] for c in class_names], [bious[c] for c in class_names]
        all_iou.extend(vi)
        all_biou.extend(vb)
        per_view.append({"view": v.name, "miou": mean_or_none(vi), "mbiou": mean_or_none(vb), "pixel_acc": None,
                         "pixel_acc_labelled": None, "iou": ious, "biou": bious, "empty_gt": empty_gt,
                         "empty_both": empty_both})
    return Ovs3dSceneResult(miou=mean_or_none(all_iou), mbiou=mean_or_none(all_biou), pixel_acc=None,
                            pixel_acc_labelled=None, per_view=per_view, skipped=[], n_views=len(views),
                            missing="error", impl=impl,
                            params={"dilation_ratio": dilation_ratio, "empty_union": EMPTY_UNION_IOU,
                                    "empty_gt_rule": EMPTY_GT_RULE, "gt_resize": "nearest-centre"},
                            empty_both=sum(len(v["empty_both"]) for v in per_view))
