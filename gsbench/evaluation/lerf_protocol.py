"""The LERF-OVS protocol (docs/protocols.md "LERF-OVS"): its frames, its size rule, its scoring and its forks.

Frames: the views with a LERF label file. Size: each label file's own size, or the training size
(`eval.resolution: train`). Relevancy against the canonical negatives; mIoU by LangSplat's mask rule.
Forks (`--protocol <fork>`), which differ only in the localisation rule:
  lerf-langsplat (default): a hit when a pixel attaining the maximum of the 30 x 30 box-filtered
      relevancy lies in a GT box (LangSplat's evaluation);
  lerf-original: a hit when the one highest-relevancy pixel of the raw map lies in a GT box (LERF's).
"""
from __future__ import annotations

from typing import Any, Optional

from gsbench.config import setting
from gsbench.errors import InputError
from gsbench.metric_table import FRAME_SET_SUFFIX
from gsbench.metrics import lerf

from .block import Block
from .frames import scoring_camera, size_text, view_name
from .labels import scene_label_masks
from .masks import score_lerf_folder
from .protocol_registry import Protocol, ProtocolContext, score_by_set

LANGSPLAT, ORIGINAL = "lerf-langsplat", "lerf-original"
LOCALIZATION = {LANGSPLAT: "langsplat", ORIGINAL: "original"}


class LerfProtocol(Protocol):
    name = "lerf"
    metrics = ("miou", "loc_acc")
    forks = (LANGSPLAT, ORIGINAL)
    order = 20
    renders_frames = True

    def supports(self, scene) -> Optional[str]:
        return None if scene.has_labels else "scene has no LERF-OVS labels"

    def frames(self, scene) -> list[int]:
        return sorted(i for i in range(len(scene.cameras)) if scene.gt_labels(i) is not None)

    def camera(self, scene, i: int, config: dict):
        return scoring_camera(scene, i, config, lambda cam: scene.label_sizes.get(i, (cam.width, cam.height)))

    def frame_query(self, scene, i: int, cam, fork: str) -> Any:
        return scene_label_masks(scene, i, cam.width, cam.height)

    def frame_texts(self, context: Any, embed, fork: str):
        queries = list(context[0])
        positives = embed(queries) if queries else None
        if positives is None:
            return None
        return lerf.lerf_texts(positives, embed(list(lerf.CANONICAL_NEGATIVES)))[0]

    def frame_output(self, cosines, context: Any, cam, fork: str) -> Any:
        """(relevancy (Q, H, W) or None, GT masks, GT boxes) of the frame."""
        masks, boxes = context
        rel = (None if cosines is None else
               lerf.relevancy_from_cosines(cosines, len(masks), cam.height, cam.width))
        return rel, masks, boxes

    def score(self, ctx: ProtocolContext) -> Block:
        return score_by_set(self, ctx)

    def _pairs(self, ctx: ProtocolContext, ids: list[int], mode: str) -> tuple[list, list, Any]:
        """(LerfPairs, cameras, kernels) of frames `ids`; one kernel size for all of them."""
        pairs, cams, kernels = [], [], None
        kmode = setting(ctx.config, "eval.lerf_kernels")
        for i in ids:
            cam = self.camera(ctx.scene, i, ctx.config)
            k = lerf.lerf_kernels(cam.width, kmode)
            if kernels is not None and k != kernels:
                raise InputError(f"scene {ctx.scene.path}: label files of different widths give different LERF "
                                 "kernels; set eval.lerf_kernels: reference")
            kernels = k
            rel, masks, boxes = ctx.frames[(self.name, mode, i)]
            for k_, q in enumerate(masks):
                pairs.append(lerf.LerfPair(view_name(ctx.scene, i), q, None if rel is None else rel[k_], masks[q],
                                           boxes[q]))
            cams.append(cam)
        return pairs, cams, kernels

    def score_set(self, ctx: ProtocolContext, ids: list[int], mode: str, frame_set: str) -> Block:
        """The metrics of frames `ids` in one query mode (ctx.frames holds their frame outputs)."""
        out, scene = Block(), ctx.scene
        names = {b: ctx.names(b, mode, frame_set) for b in self.metrics}
        every = [n for ns in names.values() for n in ns]
        if not ids:
            out.skip(every, f"no labelled LERF frame in the {frame_set} set")
            return out
        if ctx.method.embed_text(list(lerf.CANONICAL_NEGATIVES), mode) is None:
            out.skip(every, f"method {ctx.config.get('method')} has no semantic field")
            return out
        pairs, cams, kernels = self._pairs(ctx, ids, mode)
        frame_names = [view_name(scene, i) for i in ids]
        if not pairs:
            out.skip(every, f"the {frame_set} label files hold no (frame, query) pair")
            return out
        r = lerf.evaluate_lerf_scene(pairs, missing="error", kernels=kernels, localization=LOCALIZATION[ctx.fork])
        by_view: dict[str, list] = {}
        for pp in r.per_pair:
            if pp["iou"] is not None:
                by_view.setdefault(pp["frame"], []).append(pp["iou"])
        view_iou = [sum(by_view[n]) / len(by_view[n]) if by_view.get(n) else None for n in frame_names]
        impl = f"{r.impl}+query-{mode}{ctx.fork_tag()}"
        for n in names["miou"]:
            out.put(n, r.miou, impl, "no pair with a non-empty GT mask", per_view=view_iou)
        for n in names["loc_acc"]:
            out.put(n, r.loc_acc, impl, "no pair with GT boxes")
        if r.skipped:
            out.notes[f"lerf_{mode}{FRAME_SET_SUFFIX[frame_set]}_pairs"] = "; ".join(
                f"{s['frame']}/{s['query']}: {s['reason']}" for s in r.skipped)
        out.frames[f"lerf/{frame_set}"] = frame_names
        out.resolution[f"lerf/{frame_set}"] = size_text(cams)
        return out

    def preview(self, method, scene, i: int, cam, config: dict, mode: str, value: Any,
                fork: str = LANGSPLAT) -> Optional[tuple]:
        """(queries, predicted masks, GT masks, metric impl) of frame i from its frame output."""
        rel, masks, boxes = value
        if rel is None and (masks or method.embed_text(["object"], mode) is None):
            return None
        names = list(masks)
        if not names:
            return [], [], [], {}
        kernels = lerf.lerf_kernels(cam.width, setting(config, "eval.lerf_kernels"))
        pairs = [lerf.LerfPair(view_name(scene, i), q, rel[k], masks[q], boxes[q]) for k, q in enumerate(names)]
        r = lerf.evaluate_lerf_scene(pairs, missing="error", kernels=kernels, localization=LOCALIZATION[fork])
        by_query = {p["query"]: p for p in r.per_pair}
        reasons = {s["query"]: s["reason"] for s in r.skipped}
        queries, preds = [], []
        for k, q in enumerate(names):
            blended = lerf.lerf_blend(rel[k], kernels.blend)
            preds.append(lerf.lerf_mask(blended, radius=kernels.radius))
            pp = by_query.get(q, {})
            queries.append({"query": q, "iou": pp.get("iou"), "biou": None, "localized": pp.get("localized"),
                            "reason": reasons.get(q)})
        tag = "" if fork == LANGSPLAT else f"+fork-{fork}"
        return queries, preds, [masks[q] for q in names], {"iou": f"{r.impl}+query-{mode}{tag}"}

    def score_folder(self, pred_dir, layout_dir, ratio: float) -> tuple[Block, dict]:
        return score_lerf_folder(pred_dir, layout_dir, ratio)


PROTOCOL = LerfProtocol()
