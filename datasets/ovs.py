"""Open-vocabulary segmentation ground truth: the 3D-OVS and LERF-OVS label layouts.

3D-OVS: `segmentations/classes.txt` (one class per line, sorted on load) and
`segmentations/<idx>/<class>.png` (foreground where the value is 255; idx indexes the sorted image
list). Pixels claimed by two class masks are ambiguous and become -1 in the class map; the per-class
masks (`Scene.gt_class_masks`) keep them.

LERF-OVS (LangSplat ground truth): `label/<scene>/frame_XXXXX.json` with
`{info: {name, width, height}, objects: [{category, bbox, segmentation: [[x, y], ...], area, ...}]}`.
`frame_00041` is index 40 of the sorted image list. Polygons become masks with cv2.fillPoly on
int32 points (the protocol; fills the boundary pixels too) or, with method="centre", by testing
pixel centres (x + 0.5, y + 0.5) against the polygon (matches the shoelace `area` field).
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Optional

import cv2
import numpy as np

from gsbench.errors import InputError

from .base import LabelObject
from .imageio import MAX_IMAGE_PIXELS, read_gray
from .label_limits import MAX_LABEL_BYTES, MAX_OBJECTS, label_problems, too_many_points
from .nerf import read_json_input

FRAME_RE = re.compile(r"^frame_(\d+)\.json$")


# ---------------------------------------------------------------------------------------- 3D-OVS
def read_classes(seg_dir: Path) -> list[str]:
    """Sorted class names of `segmentations/classes.txt`."""
    f = Path(seg_dir) / "classes.txt"
    if not f.is_file():
        raise InputError(f"{f}: classes file not found")
    names = [ln.strip() for ln in f.read_text(encoding="utf-8").splitlines() if ln.strip()]
    if not names:
        raise InputError(f"{f}: no class names")
    for n in names:
        if not plain_name(n):
            raise InputError(f"{f}: class name {n[:80]!r} is not a plain file name (each class names the "
                             "mask file <class>.png of a view folder: no '/', '\\', NUL, '.' or '..')")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"{f}: duplicate class names {dup}")
    return sorted(names)


def plain_name(name: str) -> bool:
    """Whether `name` can stand for one file in one folder: no path separator, no NUL, not '.' or
    '..' (a class name like '../x' would make `<class>.png` a file outside the view folder)."""
    return bool(name) and not any(c in name for c in "/\\\x00") and name not in (".", "..")


def _problem(problems: list[str] | None, message: str) -> None:
    """Raise `message`, or collect it when the caller lists problems (`gsbench data check`)."""
    if problems is None:
        raise InputError(message)
    problems.append(message)


def scan_segmentations(seg_dir: Path, class_names: list[str], n_views: int,
                       problems: list[str] | None = None) -> dict[int, dict[str, Path]]:
    """view index -> {class name: mask file}; unknown classes and out-of-range views are errors
    (raised, or appended to `problems` and left out when a list is given)."""
    seg_dir = Path(seg_dir)
    out: dict[int, dict[str, Path]] = {}
    known = set(class_names)
    for d in sorted(seg_dir.iterdir()):
        if not d.is_dir() or d.name.startswith("."):
            continue
        if not d.name.isdigit():
            _problem(problems, f"{d}: segmentation folder name is not an image index")
            continue
        idx = int(d.name)
        if idx >= n_views:
            _problem(problems, f"{d}: image index {idx} but the scene has {n_views} images")
            continue
        files = {}
        for f in sorted(d.iterdir()):
            if f.suffix.lower() != ".png" or f.name.startswith("."):
                continue
            if f.stem not in known:
                _problem(problems, f"{f}: class {f.stem!r} is not in {seg_dir / 'classes.txt'}")
                continue
            files[f.stem] = f
        out[idx] = files
    return out


def read_class_masks(files: dict[str, Path], class_names: list[str], size: tuple[int, int]) -> dict[str, np.ndarray]:
    """{class: bool H x W} for every class (all False when the view has no file for it)."""
    w, h = size
    return {c: (read_gray(files[c], size) == 255) if c in files else np.zeros((h, w), bool) for c in class_names}


def masks_to_class_map(masks: dict[str, np.ndarray], class_names: list[str]) -> np.ndarray:
    """int32 class index map, -1 where no class or more than one class claims the pixel."""
    shape = next(iter(masks.values())).shape
    cmap = np.full(shape, -1, np.int32)
    count = np.zeros(shape, np.int32)
    for k, c in enumerate(class_names):
        m = masks[c]
        cmap[m] = k
        count += m
    cmap[count > 1] = -1
    return cmap


# ---------------------------------------------------------------------------------------- LERF-OVS
def find_label_dir(root: Path) -> Path | None:
    """`label/<scene>/`, `label/` with frame files, or the LangSplat `../label/<scene>/`."""
    root = Path(root)
    for cand in (root / "label" / root.name, root / "label", root.parent / "label" / root.name):
        if cand.is_dir() and any(FRAME_RE.match(p.name) for p in cand.iterdir()):
            return cand
    sub = root / "label"
    if sub.is_dir():
        dirs = [d for d in sub.iterdir() if d.is_dir() and any(FRAME_RE.match(p.name) for p in d.iterdir())]
        if len(dirs) == 1:
            return dirs[0]
    return None


def label_files(label_dir: Path, n_views: int, problems: list[str] | None = None) -> dict[int, Path]:
    """view index -> label file; frame_XXXXX is index XXXXX - 1 of the sorted image list (a frame
    beyond the images is raised, or appended to `problems` and left out when a list is given)."""
    out = {}
    for p in sorted(Path(label_dir).iterdir()):
        m = FRAME_RE.match(p.name)
        if not m:
            continue
        idx = int(m.group(1)) - 1
        if not 0 <= idx < n_views:
            _problem(problems, f"{p}: frame number {idx + 1} is outside the {n_views} images "
                               "(frame_00001 is the first)")
            continue
        out[idx] = p
    return out


def _info_size(path: Path, info: dict) -> Optional[tuple[int, int]]:
    """(W, H) of `info.width/height`, None when the file does not give them; checked positive and
    within the pixel budget of an image (the masks are drawn at this size)."""
    w, h = info.get("width"), info.get("height")
    if w is None or h is None:
        return None
    try:
        w, h = int(w), int(h)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{path}: info.width / info.height are not integers ({str(w)[:20]!r}, "
                         f"{str(h)[:20]!r})") from None
    if w < 1 or h < 1:
        raise InputError(f"{path}: label size {w}x{h} is not positive")
    if w * h > MAX_IMAGE_PIXELS:
        raise InputError(f"{path}: label size {w}x{h} is more than the {MAX_IMAGE_PIXELS} pixels of an image")
    return w, h


def label_size(path: Path, info: dict, image_name: str, width: int, height: int) -> tuple[int, int]:
    """(W, H) a label file was drawn at: `info.width/height`, else the image's size. A label of
    another aspect ratio than its image is an error (it cannot be scaled onto it)."""
    size = _info_size(path, info)
    if size is None:
        return width, height
    w, h = size
    sx, sy = width / float(w), height / float(h)
    if abs(sx - sy) > 0.01 * max(sx, sy):
        raise InputError(f"{path}: label size {w}x{h} has another aspect ratio than image {image_name} "
                         f"({width}x{height})")
    return w, h


def _points(seg, path: Path, k: int, grid: Optional[tuple[int, int]]) -> list[np.ndarray]:
    """A segmentation as a list of (K, 2) polygons: [[x, y], ...] or [[[x, y], ...], ...] or COCO flat
    lists. A huge one is refused before conversion when the label grid is known."""
    if not isinstance(seg, list) or not seg:
        raise InputError(f"{path}: object {k}: 'segmentation' is not a non-empty list")
    huge = too_many_points(path, k, len(seg), *grid) if grid else None
    if huge:
        raise InputError(huge)
    try:
        a = np.asarray(seg, dtype=np.float64)
        if a.ndim == 2 and a.shape[1] == 2:
            polys = [a]
        elif a.ndim == 3 and a.shape[2] == 2:
            polys = list(a)
        else:
            raise ValueError
    except (ValueError, TypeError):
        try:
            polys = [np.asarray(s, dtype=np.float64).reshape(-1, 2) for s in seg]
        except (ValueError, TypeError):
            raise InputError(f"{path}: object {k}: 'segmentation' is not a list of [x, y] points") from None
    for p in polys:
        if len(p) < 1 or not np.all(np.isfinite(p)):
            raise InputError(f"{path}: object {k}: polygon has no points or non-finite coordinates")
    return polys


def _numbers(value, n: Optional[int], path: Path, k: int, key: str) -> Optional[tuple]:
    """A finite number (n None) or a list of n finite numbers from an object's field, or None."""
    if value is None:
        return None
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape != (() if n is None else (n,)) or not np.all(np.isfinite(a)):
        what = "a finite number" if n is None else f"a list of {n} finite numbers"
        raise InputError(f"{path}: object {k}: '{key}' is not {what}")
    return float(a) if n is None else tuple(float(v) for v in a)


def read_lerf_label(path: Path, image_size: Optional[tuple[int, int]] = None,
                    problems: Optional[list[str]] = None) -> tuple[dict, list[LabelObject]]:
    """`info` dict and the label objects of one LERF-OVS label file, checked against the limits of
    `datasets/label_limits.py` on its grid (`info.width/height`, else `image_size` when given). A
    file that breaks a limit is refused with the first and a count, or, when `problems` is a list,
    every broken limit is appended to it and the objects returned (`gsbench data check`)."""
    path = Path(path)
    size = path.stat().st_size if path.is_file() else 0
    if size > MAX_LABEL_BYTES:
        raise InputError(f"{path}: refused: {size} bytes, more than the {MAX_LABEL_BYTES // 2**20} MiB a label "
                         "file may hold")
    d = read_json_input(path)
    if not isinstance(d, dict) or not isinstance(d.get("objects"), list):
        raise InputError(f"{path}: expected an object with an 'objects' list")
    info = d.get("info") or {}
    if not isinstance(info, dict):
        raise InputError(f"{path}: 'info' is not an object")
    grid = _info_size(path, info) or (tuple(int(v) for v in image_size) if image_size else None)
    if len(d["objects"]) > MAX_OBJECTS:
        raise InputError(f"{path}: {len(d['objects'])} objects, more than the {MAX_OBJECTS} a label file may hold")
    objs = []
    for k, o in enumerate(d["objects"]):
        if not isinstance(o, dict) or not isinstance(o.get("category"), str) or not o["category"].strip():
            raise InputError(f"{path}: object {k} has no 'category' string")
        objs.append(LabelObject(category=o["category"].strip(), polygons=_points(o.get("segmentation"), path, k, grid),
                                bbox=_numbers(o.get("bbox"), 4, path, k, "bbox"),
                                area=_numbers(o.get("area"), None, path, k, "area")))
    broken = label_problems(path, objs, *grid) if grid else []
    if broken and problems is not None:
        problems.extend(broken)
    elif broken:
        more = f" (and {len(broken) - 1} more problems in this file)" if len(broken) > 1 else ""
        raise InputError(broken[0] + more)
    return info, objs


def scale_labels(objs: list[LabelObject], sx: float, sy: float) -> list[LabelObject]:
    """Labels drawn at another resolution, moved to the image's pixel grid."""
    s = np.array([sx, sy])
    out = []
    for o in objs:
        bbox = None if o.bbox is None else (o.bbox[0] * sx, o.bbox[1] * sy, o.bbox[2] * sx, o.bbox[3] * sy)
        out.append(
            LabelObject(o.category, [p * s for p in o.polygons], bbox, None if o.area is None else o.area * sx * sy)
        )
    return out


def polygons_to_mask(polygons: list[np.ndarray], height: int, width: int, method: str = "fillpoly") -> np.ndarray:
    """bool H x W union of polygons. fillpoly: cv2.fillPoly on int32 points (the LangSplat protocol);
    centre: pixel (x, y) is inside when its centre (x + 0.5, y + 0.5) is inside the polygon."""
    mask = np.zeros((height, width), np.uint8)
    if method == "fillpoly":
        for p in polygons:
            cv2.fillPoly(mask, [np.asarray(p).astype(np.int32).reshape(-1, 1, 2)], 1)
        return mask.astype(bool)
    if method == "centre":
        from matplotlib.path import Path as MplPath

        out = np.zeros((height, width), bool)
        for p in polygons:
            p = np.asarray(p, dtype=np.float64)
            if len(p) < 3:
                continue
            x0, y0 = np.clip(np.floor(p.min(0) - 1).astype(int), 0, [width, height])
            x1, y1 = np.clip(np.ceil(p.max(0) + 1).astype(int), 0, [width, height])
            if x1 <= x0 or y1 <= y0:
                continue
            yy, xx = np.mgrid[y0:y1, x0:x1]
            inside = MplPath(p).contains_points(np.stack([xx.ravel() + 0.5, yy.ravel() + 0.5], 1))
            out[y0:y1, x0:x1] |= inside.reshape(y1 - y0, x1 - x0)
        return out
    raise ValueError(f"unknown polygon rasterisation method {method!r} (fillpoly | centre)")


def label_masks(objs: list[LabelObject], height: int, width: int, method: str = "fillpoly") -> dict[str, np.ndarray]:
    """{category: bool mask}; objects of one category are OR-ed (the protocol)."""
    out: dict[str, np.ndarray] = {}
    for o in objs:
        m = polygons_to_mask(o.polygons, height, width, method)
        out[o.category] = out[o.category] | m if o.category in out else m
    return out


def mask_to_polygons(mask: np.ndarray) -> list[np.ndarray]:
    """Polygons (int32 K x 2) whose cv2.fillPoly union is exactly `mask`.

    Outer contours of the mask, except on rows where that would fill a hole: those rows are written
    as one-row run polygons. Checked on exit; raises if the polygons do not reproduce the mask.
    """
    m = np.asarray(mask, bool)
    h, w = m.shape
    bad_rows = np.zeros(h, bool)
    for _ in range(4):
        work = m.copy()
        work[bad_rows] = False
        contours, _ = cv2.findContours(work.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        polys = [c.reshape(-1, 2).astype(np.int32) for c in contours]
        for y in np.nonzero(bad_rows)[0]:
            row = np.concatenate([[False], m[y], [False]])
            d = np.diff(row.astype(np.int8))
            for x0, x1 in zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]):
                polys.append(np.array([[x0, y], [x1 - 1, y], [x1 - 1, y], [x0, y]], np.int32))
        got = polygons_to_mask(polys, h, w, "fillpoly")
        diff = got != m
        if not diff.any():
            return polys
        bad_rows |= diff.any(axis=1)
    raise RuntimeError("mask_to_polygons: could not reproduce the mask exactly")
