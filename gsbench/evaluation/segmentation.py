"""3D-OVS and LERF-OVS scoring of a trained method, per query mode and frame set.

Query modes: "encode" (the paper: text encoded into the latent space) and "decode" (LangSplat:
latents decoded to CLIP space); each mode's metric ids end in "+query-<mode>". The un-suffixed
names carry the configured `query.mode`. Frame sets: see gsbench.evaluation.frames.

Each scored frame is rendered once for every protocol and query mode (`frame_outputs`): the
rendered latents serve the encode mode, their decoding (only when the decode mode is scored, a
block of pixels at a time, each block scored against every protocol's texts while it is in the
cache) serves the decode mode, and each protocol keeps only its small per-frame result (3D-OVS
class map, LERF relevancy maps) before the next frame is rendered.
"""
from __future__ import annotations

import logging
from typing import Optional

import numpy as np
from threadpoolctl import threadpool_limits

from gsbench.config import setting
from gsbench.config_keys import PROTOCOLS, QUERY_MODES
from gsbench.errors import InputError
from gsbench.metric_table import FRAME_SET_SUFFIX, SEG_BASES, seg_metric
from gsbench.metrics import lerf, ovs3d, pixel_norms, pixel_text_cosines
from gsbench.train.feature_blocks import FeatureBlocks

from .block import Block, to_numpy
from .frames import eval_settings, ovs3d_downsample, segmentation_camera, size_text, view_name
from .labels import class_masks, scene_label_masks

log = logging.getLogger(__name__)


def resolve_protocols(scene, protocol: str) -> tuple[list[str], dict]:
    """Which segmentation protocols to run ({protocol: reason} for the others); `auto` = every one
    the scene supports."""
    if protocol not in PROTOCOLS:
        raise InputError(f"protocol must be one of {', '.join(PROTOCOLS)}, got {protocol!r}")
    skipped = {}
    wanted = ["3dovs", "lerf"] if protocol == "auto" else [protocol]
    out = []
    for p in wanted:
        if p == "3dovs" and not scene.has_semantics:
            skipped["3dovs"] = "scene has no 3D-OVS class masks"
        elif p == "lerf" and not scene.has_labels:
            skipped["lerf"] = "scene has no LERF-OVS labels"
        else:
            out.append(p)
    if protocol != "auto" and not out:
        raise InputError(f"scene {scene.path}: protocol {protocol} requested but {skipped[protocol]}")
    return out, skipped


def _names(protocol: str, mode: str, configured: str, frame_set: str) -> dict[str, list[str]]:
    """base -> the metric names one (mode, frame set) result is stored under."""
    out = {}
    for base in SEG_BASES[protocol]:
        names = [seg_metric(base, protocol, mode, frame_set)]
        if mode == configured:
            names.append(seg_metric(base, protocol, None, frame_set))
        out[base] = names
    return out


def _text(method, texts: list[str], mode: str):
    t = method.embed_text(list(texts), mode)
    return None if t is None else to_numpy(t)


def _feature_blocks(method, cam, modes: tuple) -> dict:
    """{mode: FeatureBlocks or None} of one camera, from one render (`semantic_feature_blocks`); a
    method without it gives whole maps, one `semantic_features` call per mode."""
    many = getattr(method, "semantic_feature_blocks", None)
    if many is not None:
        return many(cam, modes)
    out = {}
    for m in modes:
        f = method.semantic_features(cam, m)
        out[m] = None if f is None else FeatureBlocks.of_map(f)
    return out


def _cosines(blocks: FeatureBlocks, groups: dict) -> dict:
    """{group: (H*W, K) cosines of every pixel with the group's (K, D) texts}, from one pass over the
    blocks: each block's pixel norms serve every group, and a decoded block is scored while it is in
    the cache (the values are those of the whole map: every pixel is on its own)."""
    parts: dict = {g: [] for g in groups}
    for b in blocks.blocks():
        b = to_numpy(b)[None]                    # (1, n, D)
        norms = pixel_norms(b, "pixel_features")
        for g, t in groups.items():
            parts[g].append(pixel_text_cosines(b, t, "pixel_features", norms)[0])
    return {g: np.concatenate(p) for g, p in parts.items()}


def _camera_key(cam) -> tuple:
    return (cam.width, cam.height, np.asarray(cam.K, np.float64).tobytes(),
            np.asarray(cam.world_to_camera, np.float64).tobytes())


def frame_outputs(method, scene, ids_by_protocol: dict, config: dict, modes: tuple) -> dict:
    """Per-frame predictions {(protocol, mode, view id): value} for the frames each protocol scores.

    3dovs: the predicted class map (None without features); lerf: (relevancy (Q, H, W) or None,
    GT masks, GT boxes). Frames are visited one at a time; each distinct camera is rendered once for
    all protocols and modes, and its features are scored a block of pixels at a time.
    """
    text_memo: dict = {}

    def text(texts: list[str], mode: str):
        key = (tuple(texts), mode)
        if key not in text_memo:
            text_memo[key] = _text(method, texts, mode)
        return text_memo[key]

    need: dict[int, list[str]] = {}
    for p, ids in ids_by_protocol.items():
        for i in ids:
            if p not in need.setdefault(i, []):
                need[i].append(p)
    # numpy's BLAS on one thread: its block products are small, and its spinning threads took the
    # cores from torch's decoder running between them (2.5x slower layers; the same bits either way)
    with threadpool_limits(limits=1, user_api="blas"):
        return _frame_outputs(method, scene, need, config, modes, text)


def _frame_outputs(method, scene, need: dict, config: dict, modes: tuple, text) -> dict:
    """`frame_outputs` of the frames in need ({view id: protocols}); text(texts, mode) embeds, memoised."""
    out = {}
    for i in sorted(need):
        by_cam: dict = {}                        # camera key -> (camera, protocols scoring at it)
        for p in need[i]:
            cam = segmentation_camera(scene, i, p, config)
            by_cam.setdefault(_camera_key(cam), (cam, []))[1].append(p)
        for cam, protocols in by_cam.values():
            blocks = _feature_blocks(method, cam, modes)
            masks, boxes = scene_label_masks(scene, i, cam.width, cam.height) if "lerf" in protocols else ({}, {})
            queries = list(masks)
            for m in modes:
                groups = {}
                classes = text(list(scene.class_names), m) if "3dovs" in protocols else None
                if classes is not None:
                    groups["3dovs"] = ovs3d.class_texts(classes)
                positives = text(queries, m) if "lerf" in protocols and queries else None
                if positives is not None:
                    groups["lerf"] = lerf.lerf_texts(positives, text(list(lerf.CANONICAL_NEGATIVES), m))[0]
                cos = _cosines(blocks[m], groups) if blocks[m] is not None and groups else {}
                if "3dovs" in protocols:
                    out[("3dovs", m, i)] = (ovs3d.ovs3d_labels(cos["3dovs"], cam.height, cam.width)
                                            if "3dovs" in cos else None)
                if "lerf" in protocols:
                    rel = (lerf.relevancy_from_cosines(cos["lerf"], len(queries), cam.height, cam.width)
                           if "lerf" in cos else None)
                    out[("lerf", m, i)] = (rel, masks, boxes)
    return out


def score_3dovs(method, scene, ids: list[int], config: dict, mode: str, configured: str,
                frame_set: str, frames: Optional[dict] = None) -> Block:
    """3D-OVS metrics of frames `ids` in one query mode (`frames`: `frame_outputs` covering them,
    computed here when not given)."""
    out = Block()
    names = _names("3dovs", mode, configured, frame_set)
    every = [n for ns in names.values() for n in ns]
    if not ids:
        out.skip(every, f"no labelled 3D-OVS frame in the {frame_set} set")
        return out
    classes = list(scene.class_names)
    text = _text(method, classes, mode)
    if text is None:
        out.skip(every, f"method {config.get('method')} has no semantic field")
        return out
    ratio = float(setting(config, "eval.boundary_dilation_ratio"))
    if frames is None:
        frames = frame_outputs(method, scene, {"3dovs": ids}, config, (mode,))
    views, cams = [], []
    for i in ids:
        cam = segmentation_camera(scene, i, "3dovs", config)
        gt = class_masks(scene, i, classes, cam.width, cam.height)
        pred = frames[("3dovs", mode, i)]
        views.append(ovs3d.Ovs3dView(view_name(scene, i), pred, gt))
        cams.append(cam)
    r = ovs3d.evaluate_ovs3d_scene(views, classes, missing="error", dilation_ratio=ratio)
    impl = f"{r.impl}+{ovs3d.PIXEL_ACC_IMPL['reference']}"
    vals = {"miou": (r.miou, r.impl), "mbiou": (r.mbiou, r.impl), "pixel_acc": (r.pixel_acc, impl),
            "pixel_acc_labelled": (r.pixel_acc_labelled, f"{r.impl}+{ovs3d.PIXEL_ACC_IMPL['labelled']}")}
    res, _ = eval_settings(config)
    down, why = ovs3d_downsample(scene, config)
    size_tag = f"+size-1/{down}" if res == "reference" else "+size-train"
    for base, (value, base_impl) in vals.items():
        pv = [v[base] for v in r.per_view]
        reason = "no view with a GT pixel (labelled pixel accuracy undefined)" if value is None else None
        for n in names[base]:
            out.put(n, value, f"{base_impl}{size_tag}+query-{mode}", reason, per_view=pv)
    if r.skipped:
        out.notes[f"3dovs_{mode}{FRAME_SET_SUFFIX[frame_set]}_views"] = "; ".join(
            f"{s['view']}: {s['reason']}" for s in r.skipped)
    out.frames[f"3dovs/{frame_set}"] = [v.name for v in views]
    out.resolution[f"3dovs/{frame_set}"] = size_text(cams)
    if res == "reference":
        out.notes["3dovs_size"] = f"1/{down} of the {size_text([scene.cameras[i] for i in ids])} images ({why})"
    return out


def score_lerf(method, scene, ids: list[int], config: dict, mode: str, configured: str, frame_set: str,
               frames: Optional[dict] = None) -> Block:
    """LERF-OVS metrics of frames `ids` in one query mode (relevancy against the canonical negatives;
    `frames`: `frame_outputs` covering them, computed here when not given)."""
    out = Block()
    names = _names("lerf", mode, configured, frame_set)
    every = [n for ns in names.values() for n in ns]
    if not ids:
        out.skip(every, f"no labelled LERF frame in the {frame_set} set")
        return out
    neg = _text(method, list(lerf.CANONICAL_NEGATIVES), mode)
    if neg is None:
        out.skip(every, f"method {config.get('method')} has no semantic field")
        return out
    kmode = setting(config, "eval.lerf_kernels")
    if frames is None:
        frames = frame_outputs(method, scene, {"lerf": ids}, config, (mode,))
    pairs, cams, kernels = [], [], None
    for i in ids:
        cam = segmentation_camera(scene, i, "lerf", config)
        k = lerf.lerf_kernels(cam.width, kmode)
        if kernels is not None and k != kernels:
            raise InputError(f"scene {scene.path}: label files of different widths give different LERF kernels; "
                             "set eval.lerf_kernels: reference")
        kernels = k
        rel, masks, boxes = frames[("lerf", mode, i)]
        queries = list(masks)
        for k_, q in enumerate(queries):
            pairs.append(lerf.LerfPair(view_name(scene, i), q, None if rel is None else rel[k_], masks[q], boxes[q]))
        cams.append(cam)
    frame_names = [view_name(scene, i) for i in ids]
    if not pairs:
        out.skip(every, f"the {frame_set} label files hold no (frame, query) pair")
        return out
    r = lerf.evaluate_lerf_scene(pairs, missing="error", kernels=kernels)
    by_view: dict[str, list] = {}
    for pp in r.per_pair:
        if pp["iou"] is not None:
            by_view.setdefault(pp["frame"], []).append(pp["iou"])
    view_iou = [sum(by_view[n]) / len(by_view[n]) if by_view.get(n) else None for n in frame_names]
    for n in names["miou"]:
        out.put(n, r.miou, f"{r.impl}+query-{mode}", "no pair with a non-empty GT mask", per_view=view_iou)
    for n in names["loc_acc"]:
        out.put(n, r.loc_acc, f"{r.impl}+query-{mode}", "no pair with GT boxes")
    if r.skipped:
        out.notes[f"lerf_{mode}{FRAME_SET_SUFFIX[frame_set]}_pairs"] = "; ".join(
            f"{s['frame']}/{s['query']}: {s['reason']}" for s in r.skipped)
    out.frames[f"lerf/{frame_set}"] = frame_names
    out.resolution[f"lerf/{frame_set}"] = size_text(cams)
    return out


def segmentation(method, scene, protocols: list[str], sets: dict, config: dict,
                 modes: tuple = QUERY_MODES, frames: Optional[dict] = None) -> Block:
    """Every protocol x frame set x query mode. sets: protocol -> {frame set: ids}. frames:
    `segmentation_frames` of the same arguments when the caller keeps them (the previews show them),
    computed here otherwise."""
    configured = query_mode(config)
    if frames is None:
        frames = segmentation_frames(method, scene, protocols, sets, config, modes)
    out = Block()
    for p in protocols:
        fn = score_3dovs if p == "3dovs" else score_lerf
        for frame_set, ids in sets[p].items():
            for m in modes:
                out.merge(fn(method, scene, ids, config, m, configured, frame_set, frames))
    return out


def segmentation_frames(method, scene, protocols: list[str], sets: dict, config: dict,
                        modes: tuple = QUERY_MODES) -> dict:
    """`frame_outputs` of every frame that `segmentation` scores (each rendered and decoded once)."""
    return frame_outputs(method, scene, {p: [i for ids in sets[p].values() for i in ids] for p in protocols},
                         config, tuple(modes))


def query_mode(config: dict) -> str:
    mode = setting(config, "query.mode")
    if mode not in QUERY_MODES:
        raise InputError(f"query.mode must be one of {', '.join(QUERY_MODES)}, got {mode!r}")
    return mode
