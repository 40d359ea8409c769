"""The 3D-OVS protocol (docs/protocols.md "3D-OVS"): its frames, its size rule, its scoring and its forks.

Frames: the views with class masks. Size: 1/`eval.ovs3d_downsample` of the images (the reference's
1/8 on a real capture, 1 on a generated scene), or the training size (`eval.resolution: train`).
Forks (`--protocol <fork>`), each scored on the same frames at the same size:
  3dovs-closed-set (default): one class per pixel, the argmax of the cosine over the scene's classes
      (the 3D-OVS reference's rule);
  3dovs-threshold: each class query its own mask, LangSplat's relevancy rule (canonical negatives,
      box blend, min-max normalisation, threshold 0.7, majority vote; `metrics.lerf`);
  3dovs-dynamic-threshold: each class query its own mask, a threshold picked per query by its
      stability and mask size (`metrics.ovs3d.dynamic_threshold`).
"""
from __future__ import annotations

from typing import Any, Optional

import numpy as np

from gsbench.config import setting
from gsbench.metric_table import FRAME_SET_SUFFIX
from gsbench.metrics import lerf, ovs3d

from .block import Block
from .frames import eval_settings, ovs3d_downsample, scoring_camera, size_text, view_name
from .labels import class_masks
from .masks import score_3dovs_folder
from .protocol_registry import Protocol, ProtocolContext, score_by_set

CLOSED_SET, THRESHOLD, DYNAMIC = "3dovs-closed-set", "3dovs-threshold", "3dovs-dynamic-threshold"
NO_PIXEL_ACC = "per-query masks (fork {fork}) do not give one class per pixel: no pixel accuracy"


class Ovs3dProtocol(Protocol):
    name = "3dovs"
    metrics = ("miou", "mbiou", "pixel_acc", "pixel_acc_labelled")
    forks = (CLOSED_SET, THRESHOLD, DYNAMIC)
    order = 10
    renders_frames = True

    def supports(self, scene) -> Optional[str]:
        return None if scene.has_semantics else "scene has no 3D-OVS class masks"

    def frames(self, scene) -> list[int]:
        ids = getattr(scene, "semantic_view_ids", None)
        if ids:
            return sorted(i for i in range(len(scene.cameras)) if i in ids)
        return sorted(i for i in range(len(scene.cameras)) if scene.gt_classes(i) is not None)

    def camera(self, scene, i: int, config: dict):
        def size(cam) -> tuple[int, int]:
            down, _ = ovs3d_downsample(scene, config)
            return max(1, cam.width // down), max(1, cam.height // down)
        return scoring_camera(scene, i, config, size)

    def frame_query(self, scene, i: int, cam, fork: str) -> Any:
        return list(scene.class_names)

    def frame_texts(self, context: Any, embed, fork: str) -> Optional[np.ndarray]:
        classes = embed(context)
        if classes is None:
            return None
        if fork == CLOSED_SET:
            return ovs3d.class_texts(classes)
        return lerf.lerf_texts(classes, embed(list(lerf.CANONICAL_NEGATIVES)))[0]

    def frame_output(self, cosines, context: Any, cam, fork: str) -> Any:
        """Closed set: the (H, W) class map; the other forks: each class's relevancy (C, H, W)."""
        if cosines is None:
            return None
        if fork == CLOSED_SET:
            return ovs3d.ovs3d_labels(cosines, cam.height, cam.width)
        return lerf.relevancy_from_cosines(cosines, len(context), cam.height, cam.width)

    def score(self, ctx: ProtocolContext) -> Block:
        return score_by_set(self, ctx)

    def score_set(self, ctx: ProtocolContext, ids: list[int], mode: str, frame_set: str) -> Block:
        """The metrics of frames `ids` in one query mode (ctx.frames holds their frame outputs)."""
        out, scene, config = Block(), ctx.scene, ctx.config
        names = {b: ctx.names(b, mode, frame_set) for b in self.metrics}
        every = [n for ns in names.values() for n in ns]
        if not ids:
            out.skip(every, f"no labelled 3D-OVS frame in the {frame_set} set")
            return out
        classes = list(scene.class_names)
        if ctx.method.embed_text(classes, mode) is None:
            out.skip(every, f"method {config.get('method')} has no semantic field")
            return out
        ratio = float(setting(config, "eval.boundary_dilation_ratio"))
        views, cams = [], []
        for i in ids:
            cam = self.camera(scene, i, config)
            gt = class_masks(scene, i, classes, cam.width, cam.height)
            pred = ctx.frames[(self.name, mode, i)]
            if ctx.fork != CLOSED_SET:
                pred = fork_masks(pred, ctx.fork, cam.width, config)
            views.append(ovs3d.Ovs3dView(view_name(scene, i), pred, gt))
            cams.append(cam)
        if ctx.fork == CLOSED_SET:
            r = ovs3d.evaluate_ovs3d_scene(views, classes, missing="error", dilation_ratio=ratio)
        else:
            impl = ovs3d.THRESHOLD_IMPL if ctx.fork == THRESHOLD else ovs3d.DYNAMIC_IMPL
            r = ovs3d.evaluate_ovs3d_masks(views, classes, impl=impl, dilation_ratio=ratio)
        self._put(out, ctx, r, names, mode, [scene.cameras[i] for i in ids])
        if r.skipped:
            out.notes[f"3dovs_{mode}{FRAME_SET_SUFFIX[frame_set]}_views"] = "; ".join(
                f"{s['view']}: {s['reason']}" for s in r.skipped)
        out.frames[f"3dovs/{frame_set}"] = [v.name for v in views]
        out.resolution[f"3dovs/{frame_set}"] = size_text(cams)
        return out

    def _put(self, out: Block, ctx: ProtocolContext, r, names: dict, mode: str, images: list) -> None:
        """The scene values of `r` under their names, with their ids and the size note."""
        impl = f"{r.impl}+{ovs3d.PIXEL_ACC_IMPL['reference']}"
        vals = {"miou": (r.miou, r.impl), "mbiou": (r.mbiou, r.impl), "pixel_acc": (r.pixel_acc, impl),
                "pixel_acc_labelled": (r.pixel_acc_labelled, f"{r.impl}+{ovs3d.PIXEL_ACC_IMPL['labelled']}")}
        res, _ = eval_settings(ctx.config)
        down, why = ovs3d_downsample(ctx.scene, ctx.config)
        size_tag = f"+size-1/{down}" if res == "reference" else "+size-train"
        closed = ctx.fork == CLOSED_SET
        for base, (value, base_impl) in vals.items():
            pv = [v[base] for v in r.per_view]
            reason = None
            if value is None:
                reason = ("no view with a GT pixel (labelled pixel accuracy undefined)" if closed
                          else NO_PIXEL_ACC.format(fork=ctx.fork))
            for n in names[base]:
                out.put(n, value, f"{base_impl}{size_tag}+query-{mode}{ctx.fork_tag()}", reason, per_view=pv)
        if res == "reference":
            out.notes["3dovs_size"] = f"1/{down} of the {size_text(images)} images ({why})"

    def preview(self, method, scene, i: int, cam, config: dict, mode: str, value: Any,
                fork: str = CLOSED_SET) -> Optional[tuple]:
        """(queries, predicted masks, GT masks, metric impl) of frame i from its frame output."""
        if value is None:
            return None
        classes = list(scene.class_names)
        gt = class_masks(scene, i, classes, cam.width, cam.height) or {}
        ratio = float(setting(config, "eval.boundary_dilation_ratio"))
        if fork == CLOSED_SET:
            m = ovs3d.ovs3d_view_metrics(value, gt, classes, dilation_ratio=ratio)
            preds = [value == k for k in range(len(classes))]
            impl = ovs3d.OVS3D_IMPL
        else:
            stack = fork_masks(value, fork, cam.width, config)
            view = ovs3d.Ovs3dView(view_name(scene, i), stack, gt)
            impl = ovs3d.THRESHOLD_IMPL if fork == THRESHOLD else ovs3d.DYNAMIC_IMPL
            m = ovs3d.evaluate_ovs3d_masks([view], classes, impl=impl, dilation_ratio=ratio).per_view[0]
            preds = list(stack)
        queries = [{"query": c, "iou": m["iou"][c], "biou": m["biou"][c], "localized": None, "reason": None}
                   for c in classes]
        gt_masks = [gt.get(c, np.zeros((cam.height, cam.width), bool)) for c in classes]
        tag = "" if fork == CLOSED_SET else f"+fork-{fork}"
        return queries, preds, gt_masks, {"iou": f"{impl}+query-{mode}{tag}"}

    def score_folder(self, pred_dir, layout_dir, ratio: float) -> tuple[Block, dict]:
        return score_3dovs_folder(pred_dir, layout_dir, ratio)


def fork_masks(relevancy: np.ndarray, fork: str, width: int, config: dict) -> np.ndarray:
    """(C, H, W) bool masks of each class's relevancy under a per-query fork."""
    if fork == THRESHOLD:
        kernels = lerf.lerf_kernels(width, setting(config, "eval.lerf_kernels"))
        return np.stack([lerf.lerf_mask(lerf.lerf_blend(r, kernels.blend), radius=kernels.radius)
                         for r in relevancy])
    return np.stack([ovs3d.dynamic_threshold_mask(r) for r in relevancy])


PROTOCOL = Ovs3dProtocol()
