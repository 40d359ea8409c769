"""The pictures of an evaluation: for a few labelled frames per protocol, the render, its depth and
each query's predicted and GT mask, with the metrics of that frame; for removal, the render before
and after. Saved in the run folder (contract: gsbench.preview_files) for the report to place.

The masks and numbers come from the same metric functions as the scores in results.json, at the
same camera (protocol, frame set, resolution, query mode), so a picture shows what was scored. In
`gsbench eval` the predictions are those the scoring computed (`frame_outputs`, kept for the shown
frames): a shown frame is not decoded again, only rendered once more for its RGB, depth and alpha.
The arrays are shrunk to `eval.preview_width` pixels wide for display only; the metrics are not.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Optional

import numpy as np

from gsbench.config import setting
from gsbench.metrics import image as MI
from gsbench.preview_files import remove_previews, write_previews
from gsbench.resize import resize_area, resize_nearest, resize_rgb

from .block import to_numpy
from .frames import view_name
from .protocol_registry import get_protocol
from .removal import REMOVAL_IMPL, removal_targets, view_removal_metrics
from .segmentation import frame_outputs

log = logging.getLogger(__name__)
DEFAULT_FRAMES = 2
DEFAULT_WIDTH = 320


def pick_frames(sets: dict[str, list[int]], n: int) -> list[tuple[int, str]]:
    """n (view, frame set) pairs spread over the held-out frames (novel views) first, then the reference ones."""
    out: list[tuple[int, str]] = []
    for frame_set in ("held-out", "reference"):
        ids = list(sets.get(frame_set, []))
        want = min(n - len(out), len(ids))
        if want <= 0:
            continue
        picks = [0] if want == 1 else [round(k * (len(ids) - 1) / (want - 1)) for k in range(want)]
        out += [(ids[k], frame_set) for k in picks]
    return out


def _to_uint8(a: np.ndarray, w: int, h: int) -> np.ndarray:
    a = np.clip(a, 0.0, 1.0).astype(np.float32)
    a = resize_area(a, w, h)
    return np.floor(a * 255.0 + 0.5).astype(np.uint8)


def _shrink_masks(masks: list[np.ndarray], w: int, h: int) -> np.ndarray:
    if not masks:
        return np.zeros((0, h, w), np.uint8)
    return np.stack([resize_nearest(np.asarray(m, bool), w, h) for m in masks]).astype(np.uint8)


def _preview_size(w: int, h: int, max_width: int) -> tuple[int, int]:
    if w <= max_width:
        return w, h
    return max_width, max(1, int(round(h * max_width / w)))


def _depth_range(depth: np.ndarray, alpha: np.ndarray) -> list[float] | None:
    """2nd and 98th percentile of the rendered depth where the render is opaque (alpha > 0.5)."""
    d = depth[(alpha > 0.5) & np.isfinite(depth) & (depth > 0)]
    if d.size == 0:
        return None
    return [float(np.percentile(d, 2)), float(np.percentile(d, 98))]


def frame_preview(method, scene, i: int, protocol: str, frame_set: str, config: dict, mode: str,
                  max_width: int, scored: Optional[dict] = None, fork: Optional[str] = None) -> tuple[dict, dict]:
    """(manifest entry, arrays) of labelled view i under `protocol` (and its fork, default when None).
    scored: evaluation's `frame_outputs` holding (protocol, mode, i), whose predictions are shown
    (nothing is decoded again); without it the frame's predictions are computed here."""
    proto = get_protocol(protocol)
    fork = fork or proto.default_fork
    cam = proto.camera(scene, i, config)
    out = method.render(cam)
    rgb = np.clip(to_numpy(out.rgb), 0.0, 1.0)
    depth, alpha = to_numpy(out.depth).astype(np.float32), to_numpy(out.alpha).astype(np.float32)
    gt = resize_rgb(np.asarray(scene.image(i), np.float32), cam.width, cam.height)
    w, h = _preview_size(cam.width, cam.height, max_width)
    entry = {"key": f"{protocol}_{Path(view_name(scene, i)).stem}", "protocol": protocol,
             "view": view_name(scene, i), "frame_set": frame_set, "scored_size": [cam.width, cam.height],
             "size": [w, h], "psnr": MI.psnr(MI.quantize_uint8(rgb), MI.quantize_uint8(gt)),
             "psnr_impl": MI.PSNR_IMPL[True], "depth_range": _depth_range(depth, alpha),
             "semantic_reason": None, "metric_impl": {}, "queries": []}
    preds: list = []
    gts: list = []
    key = (protocol, mode, i)
    if scored is None or key not in scored:
        scored = frame_outputs(method, scene, {protocol: [i]}, config, (mode,), {protocol: fork})
    shown = proto.preview(method, scene, i, cam, config, mode, scored[key], fork)
    if shown is None:
        entry["semantic_reason"] = f"method {config.get('method')} has no semantic field"
    else:
        entry["queries"], preds, gts, entry["metric_impl"] = shown
        if not entry["queries"]:
            entry["semantic_reason"] = "the label file holds no query"
    gt_depth = scene.gt_depth(i)
    gt_depth = (np.zeros((0, 0), np.float16) if gt_depth is None else
                resize_nearest(np.nan_to_num(np.asarray(gt_depth, np.float32)), w, h).astype(np.float16))
    arrays = {"render": _to_uint8(rgb, w, h), "gt": _to_uint8(gt, w, h), "gt_depth": gt_depth,
              "depth": resize_nearest(np.asarray(depth, np.float32), w, h).astype(np.float16),
              "alpha": _to_uint8(alpha, w, h),
              "pred": _shrink_masks(preds, w, h),
              "gt_masks": _shrink_masks(gts, w, h)}
    entry["file"] = f"{entry['key']}.npz"
    return entry, arrays


def removal_previews(method, scene, ids: list[int], cams: list, config: dict, n: int,
                     max_width: int) -> tuple[list[dict], dict, str | None]:
    """Before / after renders of the first removable object on up to n held-out views where it is
    visible, with that view's removal metrics; or a reason when there is nothing to show."""
    if not (scene.has_removal and scene.has_instances and scene.instance_classes):
        return [], {}, "scene has no removal ground truth (synthetic scenes only)"
    if method.embed_text(["object"], "encode") is None:
        return [], {}, f"method {config.get('method')} has no semantic field to select objects"
    threshold = float(setting(config, "removal.threshold"))
    for name, inst in removal_targets(scene):
        shown = []
        for i, cam in zip(ids, cams):
            inst_map, gt_rm = scene.gt_instances(i), scene.removed_image(i, inst)
            if inst_map is None or gt_rm is None:
                continue
            obj = resize_nearest(np.asarray(inst_map, np.int32) == inst, cam.width, cam.height)
            if obj.any():
                shown.append((i, cam, obj, resize_rgb(np.asarray(gt_rm, np.float32), cam.width, cam.height)))
            if len(shown) == n:
                break
        if not shown:
            continue
        removed, n_pruned = method.remove(name, threshold)
        entries, arrays = [], {}
        for i, cam, obj, gt_rm in shown:
            before = np.clip(to_numpy(method.render(cam).rgb), 0.0, 1.0)
            after = np.clip(to_numpy(removed.render(cam).rgb), 0.0, 1.0)
            res, ps = view_removal_metrics(after, gt_rm, obj)
            w, h = _preview_size(cam.width, cam.height, max_width)
            key = f"removal_{Path(view_name(scene, i)).stem}"
            entries.append({"key": key, "file": f"{key}.npz", "view": view_name(scene, i), "query": name,
                            "n_pruned": n_pruned, "threshold": threshold, "residual": res, "psnr_outside": ps,
                            "impl": REMOVAL_IMPL, "size": [w, h], "scored_size": [cam.width, cam.height]})
            arrays[key] = {"before": _to_uint8(before, w, h), "after": _to_uint8(after, w, h),
                           "gt_after": _to_uint8(gt_rm, w, h),
                           "object": _shrink_masks([obj], w, h)[0]}
        return entries, arrays, None
    return [], {}, "no single-instance class visible in the held-out views"


def preview_settings(config: dict) -> tuple[int, int]:
    """(frames per protocol, max width) from eval.previews / eval.preview_width."""
    return int(setting(config, "eval.previews")), int(setting(config, "eval.preview_width"))


def preview_keys(protocols: list[str], sets: dict, config: dict, mode: str) -> set:
    """The `frame_outputs` keys (protocol, mode, view id) of the frames `save_previews` shows."""
    n, _ = preview_settings(config)
    return {(p, mode, i) for p in protocols for i, _ in pick_frames(sets[p], n)} if n > 0 else set()


def save_previews(run_dir: Path, method, scene, protocols: list[str], sets: dict, rec_ids: list[int],
                  rec_cams: list, config: dict, mode: str, identity: dict,
                  scored: Optional[dict] = None, forks: Optional[dict] = None) -> Path | None:
    """Write run_dir/previews for this evaluation (none, and the old ones deleted, when eval.previews is 0).
    scored: the evaluation's `frame_outputs`, whose predictions the pictures show; forks: {protocol: fork}."""
    n, max_width = preview_settings(config)
    if n <= 0:
        remove_previews(run_dir)
        return None
    frames, arrays = [], {}
    for p in protocols:
        for i, frame_set in pick_frames(sets[p], n):
            entry, arrs = frame_preview(method, scene, i, p, frame_set, config, mode, max_width, scored,
                                        (forks or {}).get(p))
            frames.append(entry)
            arrays[entry["key"]] = arrs
    removal, rarrays, rreason = removal_previews(method, scene, rec_ids, rec_cams, config, n, max_width)
    arrays.update(rarrays)
    notes = {} if protocols else {"frames": "no segmentation protocol evaluated: no labelled frame to show"}
    manifest = {**identity, "query_mode": mode, "max_width": max_width, "frames": frames, "removal": removal,
                "removal_reason": rreason, "notes": notes}
    path = write_previews(run_dir, manifest, arrays)
    log.info("previews: %d frames, %d removal views in %s", len(frames), len(removal), path)
    return path
