"""Score another method's predicted masks (a folder of PNGs) with the protocol code.

Folder formats:
  3dovs: <pred>/<view>/<class>.png (255 = class) or <pred>/<view>.png (class index, 255 = none),
         <view> = the segmentations/<idx> folder name or the stem of the idx-th sorted image;
  lerf:  <pred>/<frame_stem>/<query>.png (non-zero = query), '/' in a query written as '_'.
The GT (LERF polygons rasterised at the label size, 3D-OVS masks) is resized to the prediction's
size by centre sampling (PIL NEAREST's rule); a prediction of another aspect ratio is refused.
A missing prediction counts as IoU 0 and is listed (count + names).
"""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Optional

import numpy as np

from gsbench import rundir
from gsbench.environment import PeakMemory, env_info
from gsbench.errors import InputError
from gsbench.metrics import segmentation as M
from gsbench.metrics.ovs3d import PIXEL_ACC_IMPL, pixel_accuracy
from gsbench.resize import NEAREST_IMPL, resize_nearest
from gsbench.results import run_results
from gsbench.store import write_json_atomic

from .block import Block
from .labels import check_aspect, label_masks, lerf_label_files, query_file, read_label_file, read_mask

MASK_FOLDER_IMPL = "mask-folder/v2"
MISSING_POLICY = "a missing prediction counts as IoU 0 (and BIoU 0) and is listed"


def score_mask_folder(pred_dir: str | os.PathLike, layout_dir: str | os.PathLike, protocol: str,
                      out_dir: Optional[str | os.PathLike] = None, dilation_ratio: float = 0.02) -> dict:
    """Score predicted masks against a LERF-OVS label folder or a 3D-OVS scene; writes
    out_dir/results.json (default: pred_dir/results.json)."""
    peaks = PeakMemory().start()
    pred_dir, layout_dir = Path(pred_dir), Path(layout_dir)
    if not pred_dir.is_dir():
        raise InputError(f"{pred_dir}: prediction folder not found")
    if not layout_dir.is_dir():
        raise InputError(f"{layout_dir}: layout folder not found")
    t0 = time.time()
    if protocol == "lerf":
        block, extra = score_lerf_folder(pred_dir, layout_dir, dilation_ratio)
    elif protocol == "3dovs":
        block, extra = score_3dovs_folder(pred_dir, layout_dir, dilation_ratio)
    else:
        raise InputError(f"mask scoring needs --protocol lerf or 3dovs, got {protocol!r}")
    identity = {"run_id": None, "method": "external", "scene": layout_dir.name, "scene_path": str(layout_dir),
                "protocol": protocol, "protocols": [protocol]}
    res = run_results(identity=identity, metrics=block.metrics, metric_impl=block.metric_impl,
                      skipped=block.skipped, per_view=block.per_view, view_names=extra.pop("view_names"),
                      frames=block.frames, frames_skipped={}, resolution=block.resolution, notes=block.notes,
                      timings={"eval_s": time.time() - t0}, memory=peaks.read(),
                      machine=env_info(), predictions=str(pred_dir), missing_policy=MISSING_POLICY, **extra)
    out = Path(out_dir) if out_dir is not None else pred_dir
    write_results(out, res)
    return res


def write_results(out: Path, res: dict) -> None:
    write_json_atomic(out / rundir.RESULTS, res)


def _check_known_names(pred_dir: Path, known: set[str], what: str, source: Path) -> None:
    """A per-query / per-class prediction file must name a known query / class: a typo would otherwise
    be ignored silently and its query scored as missing."""
    for f in sorted(pred_dir.glob("*/*.png")):
        if f.name not in known:
            names = ", ".join(sorted(k[:-4] for k in known))
            raise InputError(f"{f}: unknown {what} {f.stem!r} (not in {source}; known: {names})")


def _mean(values: list) -> Optional[float]:
    return float(np.mean(values)) if values else None


def score_lerf_folder(pred_dir: Path, layout_dir: Path, ratio: float) -> tuple[Block, dict]:
    out = Block()
    pairs, missing, view_names, view_miou, sizes = [], [], [], [], set()
    labels = [(lf, *read_label_file(lf)) for lf in lerf_label_files(layout_dir)]
    _check_known_names(pred_dir, {query_file(str(o.category)) for _, _, _, objs in labels for o in objs}, "query",
                       layout_dir)
    for lf, w, h, objects in labels:
        view_names.append(lf.stem)
        files = {q: pred_dir / lf.stem / query_file(q) for q in {str(o.category) for o in objects}}
        preds = {q: read_mask(f) != 0 for q, f in files.items() if f.exists()}
        shapes = {p.shape for p in preds.values()}
        if len(shapes) > 1:
            raise InputError(f"{pred_dir / lf.stem}: prediction masks of one frame differ in size {sorted(shapes)}")
        ph, pw = shapes.pop() if shapes else (h, w)
        check_aspect(pred_dir / lf.stem, pw, ph, w, h, f"the label file {lf.name}")
        sizes.add(f"{pw}x{ph}")
        gt_masks, _ = label_masks(objects, w, h, pw, ph)
        ious = []
        for q, gt in gt_masks.items():
            if q not in preds:
                missing.append(f"{lf.stem}/{query_file(q)}")
                pairs.append({"view": lf.stem, "query": q, "iou": 0.0, "biou": 0.0, "missing": True})
                ious.append(0.0)
                continue
            iou = M.iou(preds[q], gt, empty=1.0)
            biou = M.boundary_iou(preds[q], gt, dilation_ratio=ratio, empty=1.0)
            pairs.append({"view": lf.stem, "query": q, "iou": iou, "biou": biou, "missing": False})
            ious.append(iou)
        view_miou.append(_mean(ious))
    out.put("miou_lerf", _mean([p["iou"] for p in pairs]), f"{MASK_FOLDER_IMPL}+{M.IOU_IMPL}+lerf-labels",
            "no (frame, query) pair", per_view=view_miou)
    out.put("mbiou_lerf", _mean([p["biou"] for p in pairs]), f"{MASK_FOLDER_IMPL}+{M.BIOU_IMPL}", "no pair")
    out.put("loc_acc_lerf", None, None, "needs relevancy maps, not binary masks")
    out.frames["lerf/masks"] = view_names
    out.resolution["lerf/masks"] = ", ".join(sorted(sizes)) + " (the predictions' size; GT resized to it)"
    return out, {"view_names": view_names, "pairs": pairs, "missing": {"count": len(missing), "files": missing}}


def _views(seg: Path) -> list[Path]:
    views = sorted((d for d in seg.iterdir() if d.is_dir()), key=lambda d: (not d.name.isdigit(),
                   int(d.name) if d.name.isdigit() else 0, d.name))
    if not views:
        raise InputError(f"{seg}: no view folders segmentations/<idx>/")
    return views


def _read_gt(vd: Path, classes: list[str]) -> dict:
    gt, shape = {}, None
    for c in classes:
        f = vd / f"{c}.png"
        if f.exists():
            gt[c] = read_mask(f) == 255
            shape = gt[c].shape
    if shape is None:
        raise InputError(f"{vd}: no <class>.png masks")
    return {c: gt.get(c, np.zeros(shape, bool)) for c in classes}


def score_3dovs_folder(pred_dir: Path, layout_dir: Path, ratio: float) -> tuple[Block, dict]:
    out = Block()
    seg = layout_dir / "segmentations"
    classes_txt = seg / "classes.txt"
    if not classes_txt.exists():
        raise InputError(f"{classes_txt}: not found (a 3D-OVS scene has segmentations/classes.txt)")
    classes = sorted(c.strip() for c in classes_txt.read_text(encoding="utf-8").splitlines() if c.strip())
    if not classes:
        raise InputError(f"{classes_txt}: no classes")
    _check_known_names(pred_dir, {f"{c}.png" for c in classes}, "class", classes_txt)
    images = sorted(p for p in (layout_dir / "images").glob("*") if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    pairs, missing, view_names, sizes = [], [], [], set()
    per: dict[str, list] = {"miou": [], "mbiou": [], "reference": [], "labelled": []}
    label_maps = True
    for vd in _views(seg):
        stems = [vd.name] + ([images[int(vd.name)].stem] if vd.name.isdigit() and int(vd.name) < len(images) else [])
        gt = _read_gt(vd, classes)
        pred_files, label_map, src = None, None, None
        for s in stems:
            if (pred_dir / s).is_dir():
                src = pred_dir / s
                pred_files = {c: src / f"{c}.png" for c in classes}
                break
            if (pred_dir / f"{s}.png").exists():
                src = pred_dir / f"{s}.png"
                label_map = read_mask(src).astype(np.int32)
                break
        view_names.append(vd.name)
        if pred_files is None and label_map is None:
            missing.append(f"{vd.name} (whole view)")
            pairs += [{"view": vd.name, "class": c, "iou": 0.0, "biou": 0.0, "missing": True} for c in classes]
            for k in per:
                per[k].append(0.0)
            continue
        preds: dict = {}
        if label_map is not None:
            if np.any((label_map >= len(classes)) & (label_map != 255)):
                raise InputError(f"{src}: class index >= {len(classes)} (255 = none)")
            label_map = np.where(label_map == 255, -1, label_map)
            preds = {c: label_map == k for k, c in enumerate(classes)}
        else:
            label_maps = False
            preds = {c: read_mask(f) == 255 for c, f in pred_files.items() if f.exists()}
        shapes = {p.shape for p in preds.values()}
        if len(shapes) > 1:
            raise InputError(f"{pred_dir / stems[0]}: prediction masks of one view differ in size {sorted(shapes)}")
        gh, gw = next(iter(gt.values())).shape
        ph, pw = shapes.pop() if shapes else (gh, gw)
        check_aspect(src, pw, ph, gw, gh, f"the GT masks of view {vd.name}")
        sizes.add(f"{pw}x{ph}")
        stack = np.stack([resize_nearest(gt[c], pw, ph) for c in classes])
        ious, bious = [], []
        for k, c in enumerate(classes):
            if c not in preds:
                missing.append(f"{vd.name}/{c}.png")
                pairs.append({"view": vd.name, "class": c, "iou": 0.0, "biou": 0.0, "missing": True})
                ious.append(0.0)
                bious.append(0.0)
                continue
            iou = M.iou(preds[c], stack[k], empty=0.0)
            biou = M.boundary_iou(preds[c], stack[k], dilation_ratio=ratio, empty=0.0)
            pairs.append({"view": vd.name, "class": c, "iou": iou, "biou": biou, "missing": False})
            ious.append(iou)
            bious.append(biou)
        per["miou"].append(_mean(ious))
        per["mbiou"].append(_mean(bious))
        for rule in ("reference", "labelled"):
            per[rule].append(pixel_accuracy(label_map, stack, rule) if label_map is not None else None)
    impl = f"{MASK_FOLDER_IMPL}+{M.IOU_IMPL}+3dovs-empty0+gt-{NEAREST_IMPL}"
    out.put("miou_3dovs", _mean([p["iou"] for p in pairs]), impl, "no (view, class) pair", per_view=per["miou"])
    out.put("mbiou_3dovs", _mean([p["biou"] for p in pairs]), f"{MASK_FOLDER_IMPL}+{M.BIOU_IMPL}+3dovs-empty0",
            "no (view, class) pair", per_view=per["mbiou"])
    no_acc = "per-class mask files do not define one class per pixel"
    for name, rule in (("pixel_acc_3dovs", "reference"), ("pixel_acc_labelled_3dovs", "labelled")):
        vals = per[rule]
        if not label_maps:
            out.put(name, None, None, no_acc, per_view=vals)
        else:
            out.put_mean(name, vals, f"{MASK_FOLDER_IMPL}+{PIXEL_ACC_IMPL[rule]}", view_names)
    out.frames["3dovs/masks"] = view_names
    out.resolution["3dovs/masks"] = ", ".join(sorted(sizes)) + " (the predictions' size; GT resized to it)"
    return out, {"view_names": view_names, "pairs": pairs, "classes": classes,
                 "missing": {"count": len(missing), "files": missing}}
