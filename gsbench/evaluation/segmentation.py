"""3D-OVS and LERF-OVS scoring of a trained method, per query mode and frame set.

Query modes: "encode" (the paper: text encoded into the latent space) and "decode" (LangSplat:
latents decoded to CLIP space); each mode's metric ids end in "+query-<mode>". The un-suffixed
names carry the configured `query.mode`. Frame sets: see gsbench.evaluation.frames.

Each scored frame is rendered once for every protocol and query mode (`frame_outputs`): the
rendered latents serve the encode mode, their decoding (done once per frame, only when the decode
mode is scored) serves the decode mode, and each protocol keeps only its small per-frame result
(3D-OVS class map, LERF relevancy maps) before the next frame is rendered.
"""
from __future__ import annotations

import logging
from typing import Optional

import numpy as np

from gsbench.config import setting
from gsbench.config_keys import QUERY_MODES
from gsbench.errors import InputError
from gsbench.metric_table import FRAME_SET_SUFFIX, SEG_BASES, seg_metric
from gsbench.metrics import lerf, ovs3d, pixel_norms

from .block import Block, to_numpy
from .frames import eval_settings, ovs3d_downsample, segmentation_camera, size_text, view_name
from .labels import class_masks, scene_label_masks

log = logging.getLogger(__name__)
PROTOCOLS = ("auto", "lerf", "3dovs")


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


def _features_modes(method, cam, modes: tuple) -> dict:
    """{mode: (features as numpy, their pixel norms) or (None, None)} of one camera, from one render
    where the method allows it; the norms serve both protocols."""
    many = getattr(method, "semantic_features_modes", None)
    feats = many(cam, modes) if many is not None else {m: method.semantic_features(cam, m) for m in modes}
    out = {}
    for m, f in feats.items():
        f = None if f is None else to_numpy(f)
        out[m] = (f, None if f is None else pixel_norms(f, "pixel_features"))
    return out


def _camera_key(cam) -> tuple:
    return (cam.width, cam.height, np.asarray(cam.K, np.float64).tobytes(),
            np.asarray(cam.world_to_camera, np.float64).tobytes())


def frame_outputs(method, scene, ids_by_protocol: dict, config: dict, modes: tuple) -> dict:
    """Per-frame predictions {(protocol, mode, view id): value} for the frames each protocol scores.

    3dovs: the predicted class map (None without features); lerf: (relevancy (Q, H, W) or None,
    GT masks, GT boxes). Frames are visited one at a time; each distinct camera is rendered once for
    all protocols and modes and its features are dropped before the next frame.
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
    out = {}
    for i in sorted(need):
        by_cam: dict = {}
        for p in need[i]:
            cam = segmentation_camera(scene, i, p, config)
            key = _camera_key(cam)
            if key not in by_cam:
                by_cam[key] = _features_modes(method, cam, modes)
            feats = by_cam[key]
            if p == "3dovs":
                for m in modes:
                    t = text(list(scene.class_names), m)
                    f, norms = feats[m]
                    out[(p, m, i)] = None if f is None or t is None else ovs3d.ovs3d_predict(f, t, pixel_norms=norms)
            else:
                masks, boxes = scene_label_masks(scene, i, cam.width, cam.height)
                queries = list(masks)
                for m in modes:
                    f, norms = feats[m]
                    rel = None
                    if f is not None and queries:
                        rel = lerf.lerf_relevancy(f, text(queries, m), text(list(lerf.CANONICAL_NEGATIVES), m),
                                                  pixel_norms=norms)
                    out[(p, m, i)] = (rel, masks, boxes)
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
                 modes: tuple = QUERY_MODES) -> Block:
    """Every protocol x frame set x query mode. sets: protocol -> {frame set: ids}."""
    configured = query_mode(config)
    frames = frame_outputs(method, scene, {p: [i for ids in sets[p].values() for i in ids] for p in protocols},
                           config, tuple(modes))
    out = Block()
    for p in protocols:
        fn = score_3dovs if p == "3dovs" else score_lerf
        for frame_set, ids in sets[p].items():
            for m in modes:
                out.merge(fn(method, scene, ids, config, m, configured, frame_set, frames))
    return out


def query_mode(config: dict, default: Optional[str] = "encode") -> str:
    mode = (config.get("query") or {}).get("mode", default)
    if mode not in QUERY_MODES:
        raise InputError(f"query.mode must be one of {', '.join(QUERY_MODES)}, got {mode!r}")
    return mode
