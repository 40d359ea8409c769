"""How right the semantic supervision is before any training (synthetic scenes with GT classes).

A target pixel's class is the scene class whose text embedding has the highest cosine with the
feature of the pixel's mask (the 3D-OVS rule applied to the targets themselves). Scoring that
against the GT classes says what a perfect fit of the targets would reach on the training views:
the ceiling the supervision sets, separate from what the optimisation does with it.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np


def target_classes(masks: np.ndarray, features: Mapping[int, np.ndarray], text: np.ndarray) -> np.ndarray:
    """Per-pixel class index of the supervision target (-1 where no mask).

    Parameters
    ----------
    masks : (H, W) int array of mask ids, -1 none.
    features : mask id -> feature vector (any length D) of that mask in this view.
    text : (C, D) class text embeddings, one row per class.
    """
    out = np.full(masks.shape, -1, np.int64)
    for t in np.unique(masks[masks >= 0]):
        f = np.asarray(features[int(t)], np.float64)
        out[masks == t] = int(np.argmax(np.asarray(text, np.float64) @ f))
    return out


def target_quality(pred: Sequence[np.ndarray], gt: Sequence[np.ndarray], num_classes: int) -> dict:
    """Pixel accuracy and per-class IoU of target classes against GT classes, pooled over views.

    Pixels with a GT class count; a pixel without a target counts as wrong. A class absent from
    both GT and targets has IoU None (left out of the mean). Returns
    {"pixel_acc", "miou", "iou": [per class]}.
    """
    inter = np.zeros(num_classes)
    union = np.zeros(num_classes)
    right = total = 0
    for p, g in zip(pred, gt):
        ok = g >= 0
        right += int((p[ok] == g[ok]).sum())
        total += int(ok.sum())
        for c in range(num_classes):
            gc, pc = g == c, p == c
            inter[c] += np.count_nonzero(gc & pc)
            union[c] += np.count_nonzero(gc | pc)
    iou = [float(i / u) if u > 0 else None for i, u in zip(inter, union)]
    seen = [x for x in iou if x is not None]
    return {"pixel_acc": right / total if total else None, "miou": float(np.mean(seen)) if seen else None,
            "iou": iou}
