"""Score another method's predicted masks (a folder of PNGs) with the protocol code.

Folder formats:
  3dovs: <pred>/<view>/<class>.png (a binary mask) or <pred>/<view>.png (class index, 255 = none),
         <view> = the segmentations/<idx> folder name or the stem of the idx-th sorted image;
  lerf:  <pred>/<frame_stem>/<query>.png (a binary mask), '/' in a query written as '_'.
Every file's size is read from its header and checked before any pixel is decoded, and its values
when it is decoded (`mask_files`: the size and value rules). The GT (LERF polygons rasterised at the
label size, 3D-OVS masks) is resized to the prediction's size by centre sampling (PIL NEAREST's rule).
A missing prediction counts as IoU 0 and is listed (count + names). An empty GT mask is scored by
its protocol's reference rule (`metrics.ovs3d.EMPTY_GT_RULE`, `metrics.lerf.EMPTY_GT_RULE`); such
pairs are marked in `pairs` and counted in `notes`.
"""
from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import Optional

import numpy as np

from gsbench import rundir
from gsbench.datasets.ovs import read_classes
from gsbench.environment import PeakMemory, env_info
from gsbench.errors import InputError
from gsbench.metrics import lerf as L
from gsbench.metrics import ovs3d as O
from gsbench.metrics import segmentation as M
from gsbench.metrics.ovs3d import PIXEL_ACC_IMPL, pixel_accuracy
from gsbench.resize import NEAREST_IMPL, resize_nearest
from gsbench.results import run_results
from gsbench.store import write_json_atomic

from .block import Block
from .labels import label_masks, lerf_label_files, query_file, read_label_file, read_mask
from .mask_files import check_prediction_size, image_size, read_binary_mask, read_class_map
from .protocol_registry import Protocol, get_protocol, protocols

log = logging.getLogger(__name__)
MASK_FOLDER_IMPL = "mask-folder/v3"   # v3: header size rule, mask values read or refused (mask_files)
MISSING_POLICY = "a missing prediction counts as IoU 0 (and BIoU 0) and is listed"
UNSCORED_REASON = "not a query of that frame's label file (LangSplat queries a frame only with its own labels)"


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
    scorers = [p.name for p in protocols() if type(p).score_folder is not Protocol.score_folder]
    if protocol not in scorers:
        raise InputError(f"mask scoring needs --protocol {' or '.join(scorers)}, got {protocol!r}")
    block, extra = get_protocol(protocol).score_folder(pred_dir, layout_dir, dilation_ratio)
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
            if len(names) > 200:
                names = names[:200] + " ..."
            raise InputError(f"{f}: unknown {what} {f.stem!r} (not in {source}; known: {names})")


def _mean(values: list) -> Optional[float]:
    return float(np.mean(values)) if values else None


def read_view_masks(files: dict[str, Path], w: int, h: int, what: str, where: Path) -> tuple[dict, tuple[int, int]]:
    """The binary masks of one view that exist ({name: bool mask}) and their (width, height): every
    header is checked against the w x h GT (and the others) before any file is decoded."""
    present = {k: f for k, f in files.items() if f.exists()}
    sizes = {}
    for k, f in present.items():
        pw, ph = image_size(f)
        check_prediction_size(f, pw, ph, w, h, what)
        sizes[k] = (pw, ph)
    if len(set(sizes.values())) > 1:
        shown = ", ".join(sorted({f"{pw}x{ph}" for pw, ph in sizes.values()}))
        raise InputError(f"{where}: prediction masks of one view differ in size ({shown})")
    return {k: read_binary_mask(f) for k, f in present.items()}, next(iter(sizes.values()), (w, h))


def _empty_note(pairs: list, what: str, rule: str) -> Optional[str]:
    """How many scored pairs have an empty GT (and an empty prediction), for `notes`; None when none."""
    empty = [p for p in pairs if p.get("empty_gt")]
    if not empty:
        return None
    both = sum(1 for p in empty if p["empty_prediction"])
    return (f"{len(empty)} of {len(pairs)} {what} pairs have an empty GT mask, {both} of them an empty "
            f"prediction too; {rule}")


def score_lerf_folder(pred_dir: Path, layout_dir: Path, ratio: float) -> tuple[Block, dict]:
    out = Block()
    pairs, missing, view_names, view_miou, sizes, scored = [], [], [], [], set(), set()
    labels = [(lf, *read_label_file(lf)) for lf in lerf_label_files(layout_dir)]
    _check_known_names(pred_dir, {query_file(str(o.category)) for _, _, _, objs in labels for o in objs}, "query",
                       layout_dir)
    for lf, w, h, objects in labels:
        view_names.append(lf.stem)
        files = {q: pred_dir / lf.stem / query_file(q) for q in {str(o.category) for o in objects}}
        scored.update(f"{lf.stem}/{f.name}" for f in files.values())
        preds, (pw, ph) = read_view_masks(files, w, h, f"the label file {lf.name}", pred_dir / lf.stem)
        sizes.add(f"{pw}x{ph}")
        gt_masks, _ = label_masks(objects, w, h, pw, ph)
        ious = []
        for q, gt in gt_masks.items():
            if q not in preds:
                missing.append(f"{lf.stem}/{query_file(q)}")
                pairs.append({"view": lf.stem, "query": q, "iou": 0.0, "biou": 0.0, "missing": True})
                ious.append(0.0)
                continue
            iou = M.iou(preds[q], gt, empty=L.EMPTY_UNION_IOU)
            biou = M.boundary_iou(preds[q], gt, dilation_ratio=ratio, empty=L.EMPTY_UNION_IOU)
            pair = {"view": lf.stem, "query": q, "iou": iou, "biou": biou, "missing": False}
            if not gt.any():
                pair.update(empty_gt=True, empty_prediction=not preds[q].any())
            pairs.append(pair)
            ious.append(iou)
        view_miou.append(_mean(ious))
    out.put("miou_lerf", _mean([p["iou"] for p in pairs]), f"{MASK_FOLDER_IMPL}+{M.IOU_IMPL}+lerf-labels",
            "no (frame, query) pair", per_view=view_miou)
    out.put("mbiou_lerf", _mean([p["biou"] for p in pairs]), f"{MASK_FOLDER_IMPL}+{M.BIOU_IMPL}", "no pair")
    out.put("loc_acc_lerf", None, None, "needs relevancy maps, not binary masks")
    out.frames["lerf/masks"] = view_names
    out.resolution["lerf/masks"] = ", ".join(sorted(sizes)) + " (the predictions' size; GT resized to it)"
    note = _empty_note(pairs, "(frame, query)", L.EMPTY_GT_RULE)
    if note:
        out.notes["lerf_empty_gt"] = note
    unscored = sorted(f"{f.parent.name}/{f.name}" for f in pred_dir.glob("*/*.png")
                      if f"{f.parent.name}/{f.name}" not in scored)
    return out, {"view_names": view_names, "pairs": pairs, "missing": {"count": len(missing), "files": missing},
                 "unscored": {"count": len(unscored), "files": unscored, "reason": UNSCORED_REASON}}


def _views(seg: Path) -> list[Path]:
    views = sorted((d for d in seg.iterdir() if d.is_dir()), key=lambda d: (not d.name.isdigit(),
                   int(d.name) if d.name.isdigit() else 0, d.name))
    if not views:
        raise InputError(f"{seg}: no view folders segmentations/<idx>/")
    return views


def _read_gt(vd: Path, classes: list[str]) -> dict:
    """{class: bool mask} of one view, 255 = the class (the reference's reading); a class without a
    file has an empty GT."""
    gt, shape = {}, None
    for c in classes:
        f = vd / f"{c}.png"
        if f.exists():
            gt[c] = read_mask(f) == 255
            shape = gt[c].shape
    if shape is None:
        raise InputError(f"{vd}: no <class>.png masks")
    return {c: gt.get(c, np.zeros(shape, bool)) for c in classes}


def _read_classes(layout_dir: Path) -> list[str]:
    """The layout's class names, read and checked as the scene reader does (no `../` names)."""
    return read_classes(layout_dir / "segmentations")


def _view_prediction(pred_dir: Path, stems: list[str], classes: list[str], gw: int, gh: int, what: str):
    """(source path, {class: bool mask}, class-index map or None, (width, height)) of one view's
    prediction; source None when the view has none. Sizes are checked from the headers first."""
    for s in stems:
        if (pred_dir / s).is_dir():
            src = pred_dir / s
            preds, size = read_view_masks({c: src / f"{c}.png" for c in classes}, gw, gh, what, src)
            return src, preds, None, size
        if (pred_dir / f"{s}.png").exists():
            src = pred_dir / f"{s}.png"
            pw, ph = image_size(src)
            check_prediction_size(src, pw, ph, gw, gh, what)
            label_map = read_class_map(src, len(classes))
            return src, {c: label_map == k for k, c in enumerate(classes)}, label_map, (pw, ph)
    return None, {}, None, (gw, gh)


def score_3dovs_folder(pred_dir: Path, layout_dir: Path, ratio: float) -> tuple[Block, dict]:
    seg = layout_dir / "segmentations"
    classes = _read_classes(layout_dir)
    _check_known_names(pred_dir, {f"{c}.png" for c in classes}, "class", seg / "classes.txt")
    images = sorted(p for p in (layout_dir / "images").glob("*") if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    pairs, missing, view_names, sizes = [], [], [], set()
    per: dict[str, list] = {"miou": [], "mbiou": [], "reference": [], "labelled": []}
    label_maps = True
    for vd in _views(seg):
        stems = [vd.name] + ([images[int(vd.name)].stem] if vd.name.isdigit() and int(vd.name) < len(images) else [])
        gt = _read_gt(vd, classes)
        gh, gw = next(iter(gt.values())).shape
        src, preds, label_map, (pw, ph) = _view_prediction(pred_dir, stems, classes, gw, gh,
                                                           f"the GT masks of view {vd.name}")
        view_names.append(vd.name)
        if src is None:
            missing.append(f"{vd.name} (whole view)")
            pairs += [{"view": vd.name, "class": c, "iou": 0.0, "biou": 0.0, "missing": True} for c in classes]
            for k in per:
                per[k].append(0.0)
            continue
        label_maps = label_maps and label_map is not None
        sizes.add(f"{pw}x{ph}")
        stack = np.stack([resize_nearest(gt[c], pw, ph) for c in classes])
        view_pairs = _score_3dovs_view(vd.name, preds, stack, classes, ratio, missing)
        pairs += view_pairs
        per["miou"].append(_mean([p["iou"] for p in view_pairs]))
        per["mbiou"].append(_mean([p["biou"] for p in view_pairs]))
        for rule in ("reference", "labelled"):
            per[rule].append(pixel_accuracy(label_map, stack, rule) if label_map is not None else None)
    out = _3dovs_block(pairs, per, label_maps, view_names, sizes)
    return out, {"view_names": view_names, "pairs": pairs, "classes": classes,
                 "missing": {"count": len(missing), "files": missing}}


def _score_3dovs_view(view: str, preds: dict, stack: np.ndarray, classes: list[str], ratio: float,
                      missing: list) -> list[dict]:
    """The (view, class) pairs of one view; a class without a prediction file is appended to `missing`."""
    pairs = []
    for k, c in enumerate(classes):
        if c not in preds:
            missing.append(f"{view}/{c}.png")
            pairs.append({"view": view, "class": c, "iou": 0.0, "biou": 0.0, "missing": True})
            continue
        iou = M.iou(preds[c], stack[k], empty=O.EMPTY_UNION_IOU)
        biou = M.boundary_iou(preds[c], stack[k], dilation_ratio=ratio, empty=O.EMPTY_UNION_IOU)
        pair = {"view": view, "class": c, "iou": iou, "biou": biou, "missing": False}
        if not stack[k].any():
            pair.update(empty_gt=True, empty_prediction=not preds[c].any())
        pairs.append(pair)
    return pairs


def _3dovs_block(pairs: list, per: dict, label_maps: bool, view_names: list, sizes: set) -> Block:
    out = Block()
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
    both = [p for p in pairs if p.get("empty_gt") and p["empty_prediction"]]
    note = _empty_note(pairs, "(view, class)", O.EMPTY_GT_RULE)
    if note:
        rest = _mean([p["iou"] for p in pairs if not (p.get("empty_gt") and p["empty_prediction"])])
        if both:
            note += f"; mIoU without the {len(both)} empty/empty pairs: " + ("none left" if rest is None else
                                                                          f"{rest:.4f}")
        out.notes["3dovs_empty_gt"] = note
        if both:
            log.warning("%d of %d (view, class) pairs have an empty GT and an empty prediction, scored IoU 0 as "
                        "the 3D-OVS reference scores them (results.json notes.3dovs_empty_gt)", len(both), len(pairs))
    return out
