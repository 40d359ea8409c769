"""LERF-OVS evaluation, the LangSplat protocol (docs/protocols.md).

Per frame and text query, for each feature level l (LangSplat renders 3 SAM levels; a method
with one level passes one map):
  r_l   = min_j softmax(10 [f.t_q, f.n_j])[0]        relevancy, negatives "object", "things",
                                                     "stuff", "texture" (`lerf_relevancy`)
  r'_l  = 0.5 (r_l + mean30x30(r_l))                  (`lerf_blend`; cv2.filter2D, 30x30 box,
                                                     default anchor and BORDER_REFLECT_101)
  x_l   = (r'_l - min) / (max - min + 1e-9);  P_l = majority7x7(x_l > 0.7)   (`lerf_mask`)
  level = argmax_l max(r'_l)  (first on ties);  IoU(P_level, GT)
  localization: level = argmax_l max(mean30x30(r_l)); hit when any pixel attaining that maximum
                lies inside any GT box of the query (bounds inclusive, x = column, y = row)
Scene mIoU = plain mean over the evaluated (frame, query) pairs; localization accuracy = hits /
pairs with boxes.

Majority 7x7 (`majority_smooth`) reproduces LangSplat's `smooth`: the window is rows
[max(0, i-3), min(i+4, H-1)) and columns likewise, i.e. truncated at the image edge *and* never
containing the last row/column (an off-by-one in the reference kept for comparability;
`window="centered"` gives the plain truncated window). Ties go to background (np.argmax of the
bincount). Where the window is empty (H or W = 1) the pixel keeps its value.

Missing predictions and empty GT are never dropped silently: see `evaluate_lerf_scene`.

The empty-class rule (EMPTY_GT_RULE) follows LangSplat's evaluation (eval/evaluate_iou_loc.py): each
frame is queried only with the categories of its own label file (`set_positives(list(img_ann))`), so
a query absent from a frame's GT is never asked there; the caller builds the pairs the same way. An
empty GT mask can still occur (a polygon outside the image, or one that vanishes on a smaller grid);
the reference then computes |P & G| / |P | G| as it stands: 0 when the prediction marks a pixel, and
0 / 0 = NaN when it is empty too, which turns its scene mean into NaN. gsbench scores that last case
EMPTY_UNION_IOU = 1 (the one deviation) and marks the pair `empty_gt`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import cv2
import numpy as np

from gsbench.config_keys import LERF_KERNEL_MODES
from gsbench.errors import InputError

from ._common import as_mask, finite_float, mean_or_none, pixel_text_cosines, to_numpy, unit_rows
from .segmentation import iou

CANONICAL_NEGATIVES = ("object", "things", "stuff", "texture")
LERF_TEMPERATURE = 10.0
LERF_BLEND_KERNEL = 30
LERF_THRESHOLD = 0.7
LERF_SMOOTH_RADIUS = 3
MISSING_POLICIES = ("error", "skip", "zero")
LERF_IMPL = "lerf-ovs/langsplat/v2"   # v2: empty-GT pairs counted (EMPTY_GT_RULE)
EMPTY_UNION_IOU = 1.0   # IoU of a pair whose GT and prediction are both empty (the reference: NaN)
EMPTY_GT_RULE = "an empty GT mask is scored |P & G| / |P | G| (0 unless the prediction is empty too, then 1)"
LERF_REFERENCE_WIDTH = 985    # width of the LERF-OVS label images the 30 px / 7 px kernels were made for


@dataclass(frozen=True)
class LerfKernels:
    """Pixel sizes of the blend box and the majority window, and the id suffix that records them."""

    blend: int = LERF_BLEND_KERNEL
    radius: int = LERF_SMOOTH_RADIUS

    @property
    def tag(self) -> str:
        ref = self.blend == LERF_BLEND_KERNEL and self.radius == LERF_SMOOTH_RADIUS
        return "" if ref else f"/kernels-scaled-box{self.blend}-maj{2 * self.radius + 1}"


def lerf_kernels(label_width: int, mode: str = "auto") -> LerfKernels:
    """Kernel sizes for labels `label_width` px wide. "reference": 30 px and 7 px whatever the size.
    "auto": the same fraction of the image as on the reference labels (scale label_width / 985),
    never larger than the reference sizes: on real LERF-OVS labels it is the reference."""
    if mode not in LERF_KERNEL_MODES:
        raise InputError(f"LERF kernel mode must be one of {LERF_KERNEL_MODES}, got {mode!r}")
    if label_width < 1:
        raise InputError(f"label width must be positive, got {label_width}")
    if mode == "reference":
        return LerfKernels()
    s = min(1.0, label_width / float(LERF_REFERENCE_WIDTH))
    return LerfKernels(max(1, int(round(LERF_BLEND_KERNEL * s))), max(1, int(round(LERF_SMOOTH_RADIUS * s))))


def _sigmoid(z: np.ndarray) -> np.ndarray:
    e = np.exp(-np.abs(z))  # never overflows
    return np.where(z >= 0, 1.0 / (1.0 + e), e / (1.0 + e))


def lerf_relevancy(pixel_features: Any, query_embedding: Any, negative_embeddings: Any, *,
                   temperature: float = LERF_TEMPERATURE, pixel_norms: np.ndarray | None = None) -> np.ndarray:
    """Relevancy r in [0, 1] of each pixel for one query (D,) -> (H, W), or Q queries (Q, D) -> (Q, H, W).

    All vectors are L2-normalised first (pixels with a zero feature stay 0: relevancy 0.5).
    softmax(t [a, b])[0] is computed as the sigmoid t (a - b), which cannot overflow.
    The minimum over the negatives is taken before the sigmoid when t > 0: a - b, t x and the
    sigmoid are each monotone (also as rounded floating-point operations), so the value is the
    same with one sigmoid per pixel and query instead of one per negative.
    pixel_norms: the features' `metrics._common.pixel_norms`, when already computed.
    """
    texts, nq, single = lerf_texts(query_embedding, negative_embeddings)
    cos, (h, w) = pixel_text_cosines(pixel_features, texts, "pixel_features", pixel_norms)
    r = relevancy_from_cosines(cos, nq, h, w, temperature=temperature)
    return r[0] if single else r


def lerf_texts(query_embedding: Any, negative_embeddings: Any) -> tuple[np.ndarray, int, bool]:
    """(queries then negatives as one (Q + J, D) float64 array, Q, whether one (D,) query was given);
    InputError for a non-finite, zero or mis-shaped embedding."""
    q = finite_float(query_embedding, "query_embedding")
    single = q.ndim == 1
    q = q[None] if single else q
    n = finite_float(negative_embeddings, "negative_embeddings")
    n = n[None] if n.ndim == 1 else n
    if q.ndim != 2 or n.ndim != 2 or n.shape[0] == 0 or q.shape[1] != n.shape[1]:
        raise InputError(f"embeddings must be (D,) / (Q, D) and (J>0, D); got query {q.shape}, negatives {n.shape}")
    unit_rows(q, "query_embedding")          # zero query / negative vectors are errors
    unit_rows(n, "negative_embeddings")
    return np.concatenate([q, n]), q.shape[0], single


def relevancy_from_cosines(cosines: np.ndarray, n_queries: int, height: int, width: int, *,
                           temperature: float = LERF_TEMPERATURE) -> np.ndarray:
    """(H*W, Q + J) cosines with the `lerf_texts` rows -> (Q, H, W) relevancy: `lerf_relevancy` from
    cosines computed elsewhere (evaluation computes them a block of pixels at a time)."""
    pos, neg = cosines[:, :n_queries], cosines[:, n_queries:]
    if temperature > 0:     # worst case over the negatives: the largest negative cosine
        r = _sigmoid(temperature * (pos - neg.max(axis=1, keepdims=True)))
    else:
        r = _sigmoid(temperature * (pos[:, :, None] - neg[:, None, :])).min(axis=2)  # (HW, Q, J) -> (HW, Q)
    return r.T.reshape(-1, height, width)


def box_mean(r: Any, size: int = LERF_BLEND_KERNEL) -> np.ndarray:
    """mean size x size filter exactly as LangSplat calls it: cv2.filter2D(r, -1, ones/size^2)."""
    a = finite_float(r, "relevancy")
    if a.ndim != 2:
        raise InputError(f"relevancy: expected (H, W), got shape {a.shape}")
    k = np.full((size, size), 1.0 / (size * size), dtype=np.float64)
    return cv2.filter2D(a, cv2.CV_64F, k)


def lerf_blend(r: Any, size: int = LERF_BLEND_KERNEL) -> np.ndarray:
    """r' = 0.5 (r + mean30x30(r))."""
    a = finite_float(r, "relevancy")
    return _blend(a, box_mean(a, size))


def _blend(r: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """`lerf_blend` from r and its box mean (`box_mean`), computed once by the caller."""
    return 0.5 * (r + mean)


def majority_smooth(mask: Any, *, radius: int = LERF_SMOOTH_RADIUS, window: str = "langsplat") -> np.ndarray:
    """Majority vote in a (2 radius + 1)^2 window (see the module docstring for the window rule)."""
    m = as_mask(mask, "mask")
    if window not in ("langsplat", "centered"):
        raise InputError(f"majority window must be 'langsplat' or 'centered', got {window!r}")
    h, w = m.shape
    s = np.zeros((h + 1, w + 1), dtype=np.int64)
    s[1:, 1:] = np.cumsum(np.cumsum(m.astype(np.int64), axis=0), axis=1)
    hl, wl = (h - 1, w - 1) if window == "langsplat" else (h, w)
    i = np.arange(h)
    j = np.arange(w)
    r0 = np.maximum(0, i - radius)
    r1 = np.maximum(r0, np.minimum(i + radius + 1, hl))
    c0 = np.maximum(0, j - radius)
    c1 = np.maximum(c0, np.minimum(j + radius + 1, wl))
    ones = (s[r1[:, None], c1[None, :]] - s[r0[:, None], c1[None, :]]
            - s[r1[:, None], c0[None, :]] + s[r0[:, None], c0[None, :]])
    count = (r1 - r0)[:, None] * (c1 - c0)[None, :]
    out = 2 * ones > count
    return np.where(count > 0, out, m)


def lerf_mask(r_blend: Any, *, threshold: float = LERF_THRESHOLD, window: str = "langsplat",
              radius: int = LERF_SMOOTH_RADIUS) -> np.ndarray:
    """Predicted mask from a blended relevancy map r': min-max normalise, threshold, 7x7 majority."""
    a = finite_float(r_blend, "blended relevancy")
    if a.ndim != 2:
        raise InputError(f"blended relevancy: expected (H, W), got shape {a.shape}")
    lo, hi = float(a.min()), float(a.max())
    x = (a - lo) / (hi - lo + 1e-9)
    return majority_smooth(x > threshold, window=window, radius=radius)


def _levels(relevancy: Any, what: str) -> list[np.ndarray]:
    if isinstance(relevancy, (list, tuple)):
        maps = [finite_float(r, what) for r in relevancy]
    else:
        a = finite_float(relevancy, what)
        maps = [a] if a.ndim == 2 else list(a)
    if not maps or any(m.ndim != 2 for m in maps) or len({m.shape for m in maps}) != 1:
        raise InputError(f"{what}: expected one (H, W) map per level, all the same size")
    return maps


def select_level(blended: Sequence[np.ndarray]) -> int:
    """Index of the level whose blended map has the largest maximum (first on ties)."""
    return int(np.argmax([float(np.max(b)) for b in blended]))


def lerf_localization(relevancy_levels: Any, bboxes: Any, size: int = LERF_BLEND_KERNEL) -> bool:
    """True when an argmax pixel of mean30x30(r) (best level) lies in any box [x1, y1, x2, y2]."""
    maps = _levels(relevancy_levels, "relevancy")
    return _localized([box_mean(m, size) for m in maps], bboxes)


def _localized(avg: list[np.ndarray], bboxes: Any) -> bool:
    """`lerf_localization` from the levels' box means (`box_mean`), computed once by the caller."""
    boxes = finite_float(bboxes, "gt bboxes").reshape(-1, 4)
    if boxes.shape[0] == 0:
        raise InputError("gt bboxes: no box given for localization")
    lvl = select_level(avg)
    ys, xs = np.nonzero(avg[lvl] == avg[lvl].max())
    for x1, y1, x2, y2 in boxes:
        xa, xb = min(x1, x2), max(x1, x2)
        ya, yb = min(y1, y2), max(y1, y2)
        if np.any((xs >= xa) & (xs <= xb) & (ys >= ya) & (ys <= yb)):
            return True
    return False


LOCALIZATION_RULES = ("langsplat", "original")   # the LERF protocol's forks differ only in this rule


def lerf_localization_original(relevancy_levels: Any, bboxes: Any) -> bool:
    """The original LERF's rule: the one highest-relevancy pixel of the raw (unfiltered) map, of the
    level with the largest maximum (first level on ties), the first such pixel in row-major order
    (np.argmax), is a hit when it lies inside any box [x1, y1, x2, y2] (bounds inclusive)."""
    maps = _levels(relevancy_levels, "relevancy")
    boxes = finite_float(bboxes, "gt bboxes").reshape(-1, 4)
    if boxes.shape[0] == 0:
        raise InputError("gt bboxes: no box given for localization")
    r = maps[select_level(maps)]
    y, x = np.unravel_index(int(np.argmax(r)), r.shape)
    for x1, y1, x2, y2 in boxes:
        if min(x1, x2) <= x <= max(x1, x2) and min(y1, y2) <= y <= max(y1, y2):
            return True
    return False


@dataclass
class LerfPair:
    """One (frame, query) of a scene. relevancy: raw r per level, (L, H, W) or a list of (H, W),
    None when the method produced no prediction. gt_mask: (H, W) at the evaluation resolution
    (objects of the category OR-ed). gt_bboxes: (K, 4) x1 y1 x2 y2 at the same resolution."""

    frame: str
    query: str
    relevancy: Any | None
    gt_mask: Any | None = None
    gt_bboxes: Any | None = None


@dataclass
class LerfSceneResult:
    miou: float | None                 # mean IoU over the pairs counted in it
    loc_acc: float | None              # localization hits / pairs with boxes counted in it
    per_pair: list[dict]               # {frame, query, iou, level, localized}
    skipped: list[dict]                # {frame, query, reason} - everything not counted
    n_pairs: int
    n_iou: int
    n_loc: int
    missing: str
    impl: str = LERF_IMPL
    params: dict = field(default_factory=dict)


def evaluate_lerf_scene(pairs: Sequence[LerfPair], *, threshold: float = LERF_THRESHOLD,
                        missing: str = "error", window: str = "langsplat",
                        kernels: LerfKernels = LerfKernels(), localization: str = "langsplat") -> LerfSceneResult:
    """The whole per-scene LERF-OVS protocol.

    missing: what a pair without a prediction does. "error" (default) raises InputError naming
    it; "skip" leaves it out of the means and lists it in `skipped`; "zero" scores IoU 0 and a
    localization miss (counted in the means) and also lists it in `skipped`.
    A pair whose GT mask is empty is counted as LangSplat's evaluation counts it, |P & G| / |P | G|:
    IoU 0 when the prediction marks any pixel; when both are empty (0 / 0 there, which would make
    its mean NaN) IoU 1, the rule `eval --masks` applies too (EMPTY_GT_RULE). Such pairs carry
    "empty_gt": True. A pair without a GT mask gets no IoU and is listed in `skipped`; its
    localization still counts when it has boxes. A pair with neither a mask nor boxes is an InputError.
    localization: "langsplat" (the argmax of the box-filtered map) or "original" (`lerf_localization_original`).
    """
    if missing not in MISSING_POLICIES:
        raise InputError(f"missing must be one of {MISSING_POLICIES}, got {missing!r}")
    if localization not in LOCALIZATION_RULES:
        raise InputError(f"localization must be one of {LOCALIZATION_RULES}, got {localization!r}")
    per_pair: list[dict] = []
    skipped: list[dict] = []
    ious: list[float] = []
    hits: list[float] = []
    for p in pairs:
        tag = f"LERF pair (frame {p.frame!r}, query {p.query!r})"
        if p.gt_mask is None and p.gt_bboxes is None:
            raise InputError(f"{tag}: has neither a GT mask nor GT boxes")
        has_boxes = p.gt_bboxes is not None and to_numpy(p.gt_bboxes, "gt bboxes").size > 0
        if p.relevancy is None:
            if missing == "error":
                raise InputError(f"{tag}: no prediction for a GT label (missing='error')")
            if missing == "skip":
                skipped.append({"frame": p.frame, "query": p.query, "reason": "missing prediction"})
                continue
            skipped.append({"frame": p.frame, "query": p.query, "reason": "missing prediction, scored 0"})
            entry = {"frame": p.frame, "query": p.query, "iou": 0.0, "level": None,
                     "localized": False if has_boxes else None}
            ious.append(0.0)
            if has_boxes:
                hits.append(0.0)
            per_pair.append(entry)
            continue
        maps = _levels(p.relevancy, f"{tag} relevancy")
        avg = [box_mean(m, kernels.blend) for m in maps]        # once, for the blend and the localization
        blended = [_blend(m, a) for m, a in zip(maps, avg)]
        lvl = select_level(blended)
        entry = {"frame": p.frame, "query": p.query, "iou": None, "level": lvl, "localized": None}
        gt = None if p.gt_mask is None else as_mask(p.gt_mask, f"{tag} gt_mask")
        if gt is not None and gt.shape != maps[0].shape:
            raise InputError(f"{tag}: GT mask {gt.shape} and relevancy {maps[0].shape} differ in size; "
                             "resize the GT (NEAREST) to the evaluation resolution first")
        if gt is None:
            skipped.append({"frame": p.frame, "query": p.query, "reason": "no GT mask"})
        else:
            pred = lerf_mask(blended[lvl], threshold=threshold, window=window, radius=kernels.radius)
            entry["iou"] = iou(pred, gt, empty=EMPTY_UNION_IOU)
            if not gt.any():
                entry["empty_gt"] = True
            ious.append(entry["iou"])
        if has_boxes:
            entry["localized"] = (_localized(avg, p.gt_bboxes) if localization == "langsplat"
                                  else lerf_localization_original(maps, p.gt_bboxes))
            hits.append(1.0 if entry["localized"] else 0.0)
        per_pair.append(entry)
    return LerfSceneResult(
        miou=mean_or_none(ious), loc_acc=mean_or_none(hits), per_pair=per_pair, skipped=skipped,
        n_pairs=len(pairs), n_iou=len(ious), n_loc=len(hits), missing=missing, impl=LERF_IMPL + kernels.tag,
        params={"threshold": threshold, "window": window, "blend_kernel": kernels.blend,
                "majority_window": 2 * kernels.radius + 1,
                "temperature": LERF_TEMPERATURE, "negatives": list(CANONICAL_NEGATIVES),
                "localization": localization})
