"""Object removal on scenes with removal GT (synthetic): for each class with one instance, remove
it by its class query and compare the renders with the GT render without it."""
from __future__ import annotations

import math

import numpy as np

from gsbench.config import setting
from gsbench.metric_table import REMOVAL_METRICS
from gsbench.metrics.image import quantize_uint8
from gsbench.resize import resize_nearest, resize_rgb

from .block import Block, to_numpy

REMOVAL_IMPL = "removal/residual-absdiff0.1+psnr-outside/v1"
REMOVAL_RESIDUAL_TAU = 0.1   # an object pixel is "residual" if mean |RGB - GT without object| > this


def view_removal_metrics(pred: np.ndarray, gt_removed: np.ndarray, obj: np.ndarray) -> tuple[float, float | None]:
    """(residual, PSNR outside the object or None when the object fills the view) of one render after
    removal, against the GT render without the object; `obj` (H, W) bool must have a pixel."""
    diff = np.abs(pred - gt_removed).mean(axis=-1)
    res = float(np.count_nonzero(diff[obj] > REMOVAL_RESIDUAL_TAU)) / float(np.count_nonzero(obj))
    outside = ~obj
    if not outside.any():
        return res, None
    mse = float(np.mean((quantize_uint8(pred)[outside] - quantize_uint8(gt_removed)[outside]) ** 2))
    return res, -10.0 * math.log10(max(mse, 1e-10))


def removal_targets(scene, notes: dict | None = None) -> list[tuple[str, int]]:
    """(class name, instance) of every class with exactly one removable instance, in scoring order;
    the reason for each other class goes into `notes`."""
    notes = {} if notes is None else notes
    by_class: dict = {}
    for inst, cls in scene.instance_classes.items():
        by_class.setdefault(cls if isinstance(cls, str) else int(cls), []).append(int(inst))
    out = []
    for cls, insts in sorted(by_class.items(), key=lambda kv: str(kv[0])):
        name = cls if isinstance(cls, str) else scene.class_names[cls]
        if len(insts) != 1:
            notes[f"removal_{name}"] = f"{len(insts)} instances share the class; no GT render without all of them"
            continue
        removable = getattr(scene, "removable_instances", None)
        if removable is not None and insts[0] not in removable:
            notes[f"removal_{name}"] = "no GT render without this object"
            continue
        out.append((name, insts[0]))
    return out


def removal(method, scene, ids: list[int], cams: list, config: dict) -> Block:
    out = Block()
    if not (scene.has_removal and scene.has_instances and scene.instance_classes):
        out.skip(REMOVAL_METRICS, "scene has no removal ground truth (synthetic scenes only)")
        return out
    if not ids:
        out.skip(REMOVAL_METRICS, "no held-out view to render (train.holdout: none)")
        return out
    if method.embed_text(["object"], "encode") is None:
        out.skip(REMOVAL_METRICS, f"method {config.get('method')}: this run has no semantic field to select objects")
        return out
    threshold = float(setting(config, "removal.threshold"))
    residuals, psnrs, per_view = [], [], [[] for _ in ids]
    for name, inst in removal_targets(scene, out.notes):
        removed, n_pruned = method.remove(name, threshold)
        out.notes[f"removal_{name}"] = f"pruned {n_pruned} Gaussians"
        for k, (i, cam) in enumerate(zip(ids, cams)):
            gt_rm = scene.removed_image(i, inst)
            inst_map = scene.gt_instances(i)
            if gt_rm is None or inst_map is None:
                continue
            obj = resize_nearest(np.asarray(inst_map, np.int32) == inst, cam.width, cam.height)
            if not obj.any():
                continue   # object not visible in this view: nothing to measure
            gt_rm = resize_rgb(np.asarray(gt_rm, np.float32), cam.width, cam.height)
            pred = np.clip(to_numpy(removed.render(cam).rgb), 0.0, 1.0)
            res, ps = view_removal_metrics(pred, gt_rm, obj)
            residuals.append(res)
            per_view[k].append(res)
            if ps is not None:
                psnrs.append(ps)
    if not residuals:
        out.skip(REMOVAL_METRICS, "no single-instance class visible in the held-out views")
        return out
    out.put_mean("removal_residual", residuals, REMOVAL_IMPL)
    out.put_mean("removal_psnr_outside", psnrs, REMOVAL_IMPL)
    out.per_view["removal_residual"] = [float(np.mean(v)) if v else None for v in per_view]
    return out
