"""Ground truth for the segmentation protocols: LERF label files -> masks and boxes, 3D-OVS class
masks and their PNG reader. (Predicted mask files are read by `mask_files`.)"""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

from gsbench.datasets.imageio import read_gray
from gsbench.datasets.ovs import label_masks as rasterise
from gsbench.datasets.ovs import read_lerf_label
from gsbench.errors import InputError
from gsbench.resize import resize_nearest


def read_label_file(path: Path) -> tuple[int, int, list]:
    """(width, height, label objects) of a LERF-OVS label file; the size comes from `info`."""
    info, objs = read_lerf_label(path)
    try:
        w, h = int(info["width"]), int(info["height"])
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{path}: info.width / info.height missing or not integers") from None
    if w < 1 or h < 1:
        raise InputError(f"{path}: image size {w}x{h} is not positive")
    return w, h, objs


def label_masks(labels: list, src_w: int, src_h: int, width: int, height: int) -> tuple[dict, dict]:
    """LERF label objects drawn on a src_w x src_h grid -> {query: (height, width) bool mask, objects of
    a category OR-ed} and {query: (K, 4) boxes or None}. The polygons are rasterised on their own grid
    (cv2.fillPoly on int32 points, the protocol) and resized by centre sampling when the evaluation
    size differs, so a prediction that is the GT resampled the same way scores exactly 1."""
    sx, sy = width / float(src_w), height / float(src_h)
    masks = {q: resize_nearest(m, width, height) for q, m in rasterise(labels, src_h, src_w).items()}
    boxes: dict[str, list] = {q: [] for q in masks}
    for obj in labels:
        if obj.bbox is not None:
            x1, y1, x2, y2 = obj.bbox
            boxes[obj.category].append([x1 * sx, y1 * sy, x2 * sx, y2 * sy])
    return masks, {q: (np.asarray(v, np.float64) if v else None) for q, v in boxes.items()}


def scene_label_masks(scene, i: int, width: int, height: int) -> tuple[dict, dict]:
    """Masks and boxes of view i's label file at width x height (from the file's own pixel grid)."""
    raw = getattr(scene, "raw_labels", {}).get(i)
    if raw is not None:
        lw, lh = scene.label_sizes[i]
        return label_masks(raw, lw, lh, width, height)
    cam = scene.cameras[i]
    return label_masks(scene.gt_labels(i), cam.width, cam.height, width, height)


def class_masks(scene, i: int, classes: list[str], width: int, height: int) -> Optional[dict]:
    """{class: bool mask at width x height} of view i (overlapping claims kept), or None without GT.
    Resized by centre sampling (`resize_nearest`) when the evaluation size differs."""
    loader = getattr(scene, "class_masks_loader", None)
    if loader is not None:
        m = loader(i)
        if m is None:
            return None
        return {c: resize_nearest(np.asarray(v, bool), width, height) for c, v in m.items()}
    gt = scene.gt_classes(i)
    if gt is None:
        return None
    gt = resize_nearest(np.asarray(gt, np.int32), width, height)
    return {c: gt == k for k, c in enumerate(classes)}


def read_mask(path: Path) -> np.ndarray:
    """First channel of a GT mask PNG (3D-OVS GT: 255 = the class), read as every image is
    (`read_gray`: its EXIF orientation applied, an unreadable file one InputError naming it)."""
    return read_gray(path)


def query_file(query: str) -> str:
    """File name of a query's mask ('/' in a query written as '_')."""
    return query.replace("/", "_") + ".png"


def lerf_label_files(layout_dir: Path) -> list[Path]:
    """The frame_*.json label files of a LERF-OVS label folder (the names the scene reader takes too).

    A scene folder given instead of its label folder is named as such, with where its labels are."""
    files = sorted(layout_dir.glob("frame_*.json"))
    if files:
        return files
    nested = sorted({p.parent for p in layout_dir.glob("label/*/frame_*.json")})
    if nested:
        where = f"this looks like a scene folder; its labels are in {', '.join(str(d) for d in nested)}"
    else:
        where = ("LERF-OVS label files usually sit in <scene>/label/<scene name>/ "
                 "(LangSplat's release: lerf_ovs/label/<scene>/)")
    raise InputError(f"{layout_dir}: holds no frame_*.json label files; {where}")
