"""Masks from labelled views: the `gt` mask provider on scenes without instance maps (real layouts).

The oracle-mask setting papers use as an upper bound, read from the labels a real dataset ships:

- 3D-OVS class masks: one segment per class and 8-connected component (pixels two classes claim
  are ambiguous, -1 in the class map, and belong to no segment);
- LERF-OVS label files: one segment per label object (polygons rasterised on the label file's own
  grid, as the evaluation does, then resized by centre sampling); larger objects are painted first
  so that a small object lying on a larger one keeps its pixels.

Segment ids are class-major, `class index * COMPONENT_STRIDE + rank` (rank: components by size,
largest first; label objects in file order), so an id always stands for one class or category and
track-mean features average one class. A view without labels has no segment (-1 everywhere): no
semantic target and no semantic loss there. The class map of a labelled view names each
segment's class, which the weight-free feature space encodes (`gsbench.priors.features`).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass

import cv2
import numpy as np

from gsbench.datasets.ovs import polygons_to_mask
from gsbench.errors import InputError
from gsbench.resize import resize_nearest

COMPONENT_STRIDE = 10_000
SOURCE_3DOVS = "3dovs-class-components"
SOURCE_LERF = "lerf-label-objects"
SOURCE_TEXT = {SOURCE_3DOVS: "3D-OVS class masks", SOURCE_LERF: "LERF-OVS label polygons"}


@dataclass
class LabelledView:
    """Segments and classes of one labelled view at the requested size."""

    segments: np.ndarray  # int32 (H, W), class-major segment id, -1 none
    classes: np.ndarray   # int32 (H, W), index into `names`, -1 none
    names: list[str]


def label_source(scene) -> str | None:
    """Which labels the scene can give masks from (3D-OVS class masks first), or None."""
    if scene.has_semantics:
        return SOURCE_3DOVS
    if scene.has_labels:
        return SOURCE_LERF
    return None


def labelled_views(scene) -> list[int]:
    """The views that carry the labels `label_source` reads."""
    src = label_source(scene)
    if src == SOURCE_3DOVS:
        ids = list(getattr(scene, "semantic_view_ids", []) or [])
        return ids or [i for i in range(len(scene.cameras)) if scene.gt_classes(i) is not None]
    if src == SOURCE_LERF:
        return list(getattr(scene, "label_view_ids", []) or [])
    return []


def _components(classes: np.ndarray, n_classes: int) -> np.ndarray:
    seg = np.full(classes.shape, -1, np.int32)
    for k in range(n_classes):
        m = (classes == k).astype(np.uint8)
        if not m.any():
            continue
        n, lab = cv2.connectedComponents(m, connectivity=8)
        if n - 1 >= COMPONENT_STRIDE:
            raise InputError(f"class {k}: {n - 1} connected components in one view (at most {COMPONENT_STRIDE - 1})")
        sizes = np.bincount(lab.ravel(), minlength=n)[1:]
        order = np.argsort(-sizes, kind="stable")            # largest first, ties in label order
        for rank, c in enumerate(order):
            seg[lab == c + 1] = k * COMPONENT_STRIDE + rank
    return seg


def _lerf_view(scene, view: int, size: tuple[int, int]) -> LabelledView | None:
    raw = getattr(scene, "raw_labels", {}).get(view)
    if raw is not None:
        lw, lh = scene.label_sizes[view]
    else:
        raw = scene.gt_labels(view)
        if raw is None:
            return None
        lw, lh = scene.cameras[view].width, scene.cameras[view].height
    names = sorted({o.category for o in raw} | set(scene.queries))
    index = {c: k for k, c in enumerate(names)}
    masks, ids, rank = [], [], {}
    for o in raw:
        k = index[o.category]
        r = rank.get(k, 0)
        rank[k] = r + 1
        if r >= COMPONENT_STRIDE:
            raise InputError(f"view {view}: more than {COMPONENT_STRIDE - 1} label objects of {o.category!r}")
        masks.append(resize_nearest(polygons_to_mask(o.polygons, lh, lw), *size))
        ids.append((k * COMPONENT_STRIDE + r, k))
    W, H = size
    seg = np.full((H, W), -1, np.int32)
    cls = np.full((H, W), -1, np.int32)
    for j in sorted(range(len(masks)), key=lambda j: -int(masks[j].sum())):
        seg[masks[j]] = ids[j][0]
        cls[masks[j]] = ids[j][1]
    return LabelledView(seg, cls, names)


def label_view(scene, view: int, size: tuple[int, int]) -> LabelledView | None:
    """Segments and classes of `view` at `size` = (W, H); None when the view has no labels."""
    src = label_source(scene)
    if src == SOURCE_3DOVS:
        c = scene.gt_classes(view)
        if c is None:
            return None
        cls = resize_nearest(np.asarray(c).astype(np.int32), *size)
        return LabelledView(_components(cls, len(scene.class_names)), cls, list(scene.class_names))
    if src == SOURCE_LERF:
        return _lerf_view(scene, view, size)
    raise InputError(f"{scene.path}: the scene has no 3D-OVS class masks and no LERF-OVS labels to take masks from")


def label_masks(scene, views, size: tuple[int, int]) -> tuple[dict[int, np.ndarray], int]:
    """{view: segment map} (all -1 for a view without labels) and the number of labelled views."""
    W, H = size
    out, n = {}, 0
    for v in views:
        lv = label_view(scene, v, size)
        out[v] = np.full((H, W), -1, np.int32) if lv is None else lv.segments
        n += lv is not None
    return out, n


def label_digest(scene, views) -> str:
    """sha256 of the labels of `views` as loaded (class maps / polygons): an edited label file
    changes the cache key of the masks taken from it, which the scene fingerprint does not cover."""
    h = hashlib.sha256(str(label_source(scene)).encode())
    for v in sorted(int(x) for x in views):
        h.update(f"|{v}:".encode())
        if label_source(scene) == SOURCE_3DOVS:
            c = scene.gt_classes(v)
            h.update(b"none" if c is None else np.ascontiguousarray(c, dtype=np.int32).tobytes()
                     + str(np.shape(c)).encode())
        else:
            raw = getattr(scene, "raw_labels", {}).get(v)
            objs = raw if raw is not None else scene.gt_labels(v)
            if objs is None:
                h.update(b"none")
                continue
            h.update(str(scene.label_sizes.get(v)).encode())
            for o in objs:
                h.update(o.category.encode())
                for p in o.polygons:
                    h.update(np.ascontiguousarray(p, dtype=np.float64).tobytes())
    return h.hexdigest()
