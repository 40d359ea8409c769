"""prepare_priors: the one entry point methods call to get order, depth, masks and features.

The ordering statistics (`stats`) use the metric implementations of `gsbench.metrics.ordering`:
`ordering_adjacent_mask_iou` (ids in both frames, GT-depth warp), `..._strict` (every id, new
tracks count as misses, GT-depth warp) and `..._flow` (strict, optical-flow warp: also on scenes
without GT depth). `priors.features.per_track: true` gives every view of a track the mean of its
per-view features (renormalised), as methods that pool CLIP features per track do.

Each part is computed by its provider (ids recorded in `Priors.providers`), cached on disk by a
content hash (`gsbench.priors.cache`), and reused on the next call with the same inputs. Depth
noise (the depth-noise study) is applied after the cache, to the depth prior only.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from tqdm.auto import tqdm

from gsbench import rundir
from gsbench.errors import InputError
from gsbench.metrics import ordering as MO
from gsbench.priors import depth as D
from gsbench.priors import labels as L
from gsbench.priors import masks as M
from gsbench.priors import propagation as P
from gsbench.priors import segmenter as S
from gsbench.priors import warp as W
from gsbench.priors.cache import PriorCache, cache_key, scene_content_hash
from gsbench.priors.features import FeatureProvider, TextAlignedFeatures, get_feature_provider
from gsbench.priors.ordering import ORDERINGS, camera_centers, order_views
from gsbench.priors.sfm_depth import points_digest
from gsbench.resize import resize_area, resize_nearest

MASK_PROVIDERS = ("simulated", "gt", "sam2")
PROPAGATORS = ("flow", "reproject")
PIPELINE_VERSION = 2


@dataclass
class Priors:
    """Everything a method gets from the priors stage: the one interface between priors and methods (docs/priors.md)."""

    order: list[int]
    depth: dict[int, D.DepthPrior] | None
    masks: dict[int, np.ndarray] | None
    mask_features: dict[tuple[int, int], np.ndarray] | None
    feature_provider: FeatureProvider | None
    providers: dict
    skipped: dict
    stats: dict
    cache: dict = field(default_factory=dict)   # part -> {"key": str, "hit": bool}


def _check_inputs(scene, view_ids: Sequence[int], image_size) -> tuple[list[int], tuple[int, int]]:
    views = [int(v) for v in view_ids]
    if not views:
        raise InputError(f"{scene.path}: prepare_priors needs at least one view")
    if len(set(views)) != len(views):
        raise InputError(f"{scene.path}: prepare_priors: duplicate view ids")
    bad = [v for v in views if not 0 <= v < len(scene.cameras)]
    if bad:
        raise InputError(f"{scene.path}: view ids {bad} out of range (scene has {len(scene.cameras)} cameras)")
    try:
        w, h = (int(image_size[0]), int(image_size[1]))
    except (TypeError, ValueError, IndexError):
        raise InputError(f"prepare_priors: image_size must be (W, H), got {image_size!r}") from None
    if w < 1 or h < 1:
        raise InputError(f"prepare_priors: image_size must be positive, got {image_size!r}")
    return views, (w, h)


def _folder_signature(path: str | None) -> list:
    """Names, sizes and mtimes of a model folder's / file's contents (part of the cache key)."""
    if not path:
        return []
    p = Path(path)
    files = sorted(q for q in p.rglob("*") if q.is_file()) if p.is_dir() else ([p] if p.exists() else [])
    return [[str(q.relative_to(p) if p.is_dir() else q.name), q.stat().st_size, int(q.stat().st_mtime)] for q in files]


class _Images:
    """Training-resolution images, loaded once on first use."""

    def __init__(self, scene, size):
        self.scene, self.size, self._d = scene, size, {}

    def __getitem__(self, v: int) -> np.ndarray:
        if v not in self._d:
            self._d[v] = resize_area(np.asarray(self.scene.image(v), dtype=np.float32), *self.size)
        return self._d[v]

    def all(self, views):
        return {v: self[v] for v in views}


def _gt_depths(scene, views, size):
    depths, valids = {}, {}
    for v in views:
        z = resize_nearest(np.asarray(scene.gt_depth(v), dtype=np.float32), *size)
        depths[v] = z
        valids[v] = np.isfinite(z) & (z > W.NEAR)
    return depths, valids


def _mask_provider_id(masks_cfg: Mapping, per_frame: bool, scene=None) -> str:
    """The masks' provider id; `gt` names where its masks come from: the scene's instance maps, or
    (a scene without them, e.g. a real layout) its labels (`gsbench.priors.labels`)."""
    p = masks_cfg.get("provider", "simulated")
    if p == "gt":
        if scene is None or scene.has_instances:
            return "gt-instances"
        return f"gt-labels:{L.label_source(scene)}"
    if p == "simulated":
        knobs = S.SegmenterKnobs.from_config(masks_cfg)
        tail = "per-frame" if per_frame else f"carry-{masks_cfg.get('propagator', 'flow')}"
        if not per_frame and masks_cfg.get("new_objects", "uncarried") != "uncarried":
            tail += f"+new-{masks_cfg['new_objects']}"
        return f"sam-sim-v{S.SEGMENTER_VERSION}:{knobs.tag()}+{tail}"
    raise InputError(f"priors.masks.provider: unknown provider {p!r} (expected one of {', '.join(MASK_PROVIDERS)})")


def _compute_masks(scene, masks_cfg: Mapping, views, order, size, images: _Images, per_frame: bool,
                   seed: int, progress: bool, device: str | None = None) -> tuple[dict[int, np.ndarray], str]:
    p = masks_cfg.get("provider", "simulated")
    if p == "sam2":
        sam = M.Sam2Masks(masks_cfg, device=device)
        imgs = images.all(order)
        if per_frame:
            return sam.per_frame(views, imgs, progress), sam.id + "+per-frame"
        return sam.propagate(order, imgs, progress), sam.id + "+video"
    pid = _mask_provider_id(masks_cfg, per_frame, scene)
    if p == "gt":
        if not scene.has_instances:
            return L.label_masks(scene, views, size)[0], pid
        return {v: M.gt_instance_map(scene, v, size) for v in views}, pid
    # simulated
    knobs = S.SegmenterKnobs.from_config(masks_cfg)
    gdepth = _gt_depths(scene, views, size)[0] if scene.has_depth else {}
    segs = {v: S.segment_view(M.gt_instance_map(scene, v, size), knobs, D.view_rng(seed, v, "sim-masks"),
                              images[v] if knobs.texture > 0 else None, gdepth.get(v))
            for v in tqdm(views, desc="simulated segments", disable=not progress, leave=False)}
    if per_frame:
        return segs, pid
    prop = masks_cfg.get("propagator", "flow")
    if prop == "flow":
        warper = P.FlowWarper(images.all(order))
    elif prop == "reproject":
        if not scene.has_depth:
            raise InputError(f"{scene.path}: priors.masks.propagator=reproject needs metric depth (GT depth) "
                             "and the scene has none; use propagator=flow")
        depths, valids = _gt_depths(scene, views, size)
        warper = P.ReprojectWarper({v: W.camera_at(scene.cameras[v], size) for v in views}, depths, valids)
    else:
        raise InputError(f"priors.masks.propagator: unknown propagator {prop!r} "
                         f"(expected one of {', '.join(PROPAGATORS)})")
    min_iou = float(masks_cfg.get("min_iou", P.DEFAULT_MIN_IOU))
    rule = masks_cfg.get("new_objects", "uncarried")
    if rule not in P.NEW_OBJECT_RULES:
        raise InputError(f"priors.masks.new_objects: unknown rule {rule!r} "
                         f"(expected one of {', '.join(P.NEW_OBJECT_RULES)})")
    return P.propagate(order, segs, warper, min_iou=min_iou, new_objects=rule, progress=progress), pid


def _mask_stats(scene, views, order, size, masks, images: _Images, per_frame: bool) -> tuple[dict, dict]:
    """The ordering study's adjacent mask IoUs of the masks in `order`, with a reason for each missing one."""
    stats, skipped = {}, {}
    strict_keys = ("ordering_adjacent_mask_iou", "ordering_adjacent_mask_iou_strict",
                   "ordering_adjacent_mask_iou_flow")
    if per_frame:
        for k in strict_keys:
            stats[k] = None
            skipped[k] = "per-frame masks are not propagated"
        return stats, skipped
    stats["ordering_adjacent_mask_iou_flow"] = MO.adjacent_mask_iou_flow(
        [masks[v] for v in order], [images[v] for v in order])
    if not scene.has_depth:
        for k in strict_keys[:2]:
            stats[k] = None
            skipped[k] = "the scene has no GT depth to warp masks between views (see the _flow variant)"
    else:
        gd, gv = _gt_depths(scene, views, size)
        cams = [W.camera_at(scene.cameras[v], size) for v in order]
        zs = [np.where(gv[v], gd[v], 0.0) for v in order]
        ms = [masks[v] for v in order]
        stats["ordering_adjacent_mask_iou"] = MO.adjacent_mask_iou(ms, zs, cams)
        stats["ordering_adjacent_mask_iou_strict"] = MO.adjacent_mask_iou_strict(ms, zs, cams)
    return stats, skipped


def prepare_priors(scene, priors_cfg: dict, view_ids: list[int], image_size: tuple[int, int],
                   cache_dir: Path | None, need_depth: bool, need_masks: bool, need_features: bool,
                   per_frame_masks: bool = False, seed: int = 0, progress: bool = True,
                   device: str | None = None) -> Priors:
    """Order the views, then compute (or load from the cache) the depth, mask and feature priors.
    Prior models (Depth Anything, SAM2, OpenCLIP) run on `device`, the run's training device (None =
    CUDA when available, else the CPU); the priors themselves are host arrays.

    `image_size` is the training resolution (W, H); every prior is at that size. Features need
    masks, so `need_features` computes masks too. `per_frame_masks=True` gives unpropagated
    per-view masks (ids not consistent across views): the twostage baseline's input.
    """
    cfg = priors_cfg or {}
    views, size = _check_inputs(scene, view_ids, image_size)
    cache = PriorCache(cache_dir)
    seed = int(seed)
    providers: dict = {"depth": None, "masks": None, "features": None}
    skipped: dict = {}
    stats: dict = {}
    cache_info: dict = {}
    stages = 1 + int(need_depth) + int(need_masks or need_features) + int(need_features)
    bar = tqdm(total=stages, desc="priors", disable=not progress)

    # ---------------------------------------------------------------- ordering
    mode = cfg.get("ordering", "pose")
    if mode not in ORDERINGS:
        raise InputError(f"priors.ordering: unknown ordering {mode!r} (expected one of {', '.join(ORDERINGS)})")
    order = order_views(scene.cameras, views, mode, seed)
    providers["ordering"] = mode
    stats["ordering_adjacent_distance"] = MO.mean_adjacent_distance(camera_centers(scene.cameras, order),
                                                                    list(range(len(order))))
    bar.update(1)

    content = None

    def scene_content():
        nonlocal content
        if content is None:
            content = {"scene": scene_content_hash(scene), "views": sorted(views), "size": list(size)}
        return content

    images = _Images(scene, size)

    # ---------------------------------------------------------------- depth
    depth = None
    if need_depth:
        dcfg = dict(cfg.get("depth", {}) or {})
        pid = D.depth_provider_id(dcfg)
        if pid is None:
            skipped["depth"] = "priors.depth.provider=none"
        else:
            params = {k: v for k, v in dcfg.items() if k != "noise"}
            params["seed"] = seed
            params["model_files"] = (_folder_signature(dcfg.get("model_path"))
                                     if dcfg.get("provider") == "depth-anything" else [])
            if dcfg.get("provider") == "sfm":   # the scene fingerprint leaves the points out
                params["points"] = points_digest(scene)
            key = cache_key("depth", pid, PIPELINE_VERSION, params, scene_content())
            hit = cache.load("depth", key)
            if hit is not None:
                arrays, meta = hit
                depth = {v: D.DepthPrior(arrays[f"values_{v}"], arrays[f"valid_{v}"].astype(bool),
                                         meta["kind"], meta["provider"]) for v in views}
            else:
                depth = D.compute_depth(scene, dcfg, views, size, seed, progress, device=device)
                kinds = {p.kind for p in depth.values()}
                arrays = {}
                for v, p in depth.items():
                    arrays[f"values_{v}"] = p.values
                    arrays[f"valid_{v}"] = p.valid
                first = depth[views[0]]
                cache.save("depth", key, arrays, {"kind": first.kind, "provider": first.provider,
                                                  "kinds": sorted(kinds)})
            cache_info["depth"] = {"key": key, "hit": hit is not None}
            depth = D.apply_depth_noise(depth, dcfg.get("noise"), seed)
            providers["depth"] = depth[views[0]].provider
        bar.update(1)
    else:
        skipped["depth"] = "not needed by the method"

    # ---------------------------------------------------------------- masks
    masks = None
    mkey = None
    if need_masks or need_features:
        mcfg = dict(cfg.get("masks", {}) or {})
        prov = mcfg.get("provider", "simulated")
        if prov not in MASK_PROVIDERS:
            raise InputError(f"priors.masks.provider: unknown provider {prov!r} "
                             f"(expected one of {', '.join(MASK_PROVIDERS)})")
        params = dict(mcfg)
        params.update(seed=seed, per_frame=bool(per_frame_masks),
                      order=list(order) if (prov != "gt" and not per_frame_masks) else None,
                      sim_version=M.SIM_VERSION)
        if prov == "sam2":
            params["model_files"] = _folder_signature(mcfg.get("checkpoint"))
        from_labels = prov == "gt" and not scene.has_instances
        if from_labels:
            params["labels"] = L.label_digest(scene, views)
        mkey = cache_key("masks", prov, PIPELINE_VERSION, params, scene_content())
        hit = cache.load("masks", mkey)
        if hit is not None:
            arrays, meta = hit
            masks = {v: arrays[f"m_{v}"].astype(np.int32) for v in views}
            mid = meta["provider"]
        else:
            masks, mid = _compute_masks(scene, mcfg, views, order, size, images, bool(per_frame_masks), seed, progress,
                                        device=device)
            cache.save("masks", mkey, {f"m_{v}": masks[v] for v in views}, {"provider": mid})
        cache_info["masks"] = {"key": mkey, "hit": hit is not None}
        providers["masks"] = mid
        ids = np.unique(np.concatenate([m[m >= 0].ravel() for m in masks.values()])) if masks else []
        stats["mask_tracks"] = int(len(ids))
        if from_labels:   # views without labels have no segment, hence no semantic target
            stats["mask_labelled_views"] = int(sum(bool((masks[v] >= 0).any()) for v in views))
        # adjacent mask IoU of the propagated masks (the ordering study's second metric): optical flow
        # and depth warps over every view pair, so cached too (keyed by the masks and the order)
        skey = cache_key("mask-stats", mid, PIPELINE_VERSION, {"order": list(order)}, {"masks": mkey})
        shit = cache.load("mask-stats", skey)
        if shit is not None:
            mstats, mskipped = shit[1]["stats"], shit[1]["skipped"]
        else:
            mstats, mskipped = _mask_stats(scene, views, order, size, masks, images, per_frame_masks)
            cache.save("mask-stats", skey, {}, {"stats": mstats, "skipped": mskipped})
        stats.update(mstats)
        skipped.update(mskipped)
        cache_info["mask-stats"] = {"key": skey, "hit": shit is not None}
        bar.update(1)
    else:
        skipped["masks"] = "not needed by the method"

    # ---------------------------------------------------------------- features
    mask_features = None
    fprov = None
    if need_features:
        fprov = get_feature_provider(dict(cfg.get("features", {}) or {}), device=device)
        fparams = dict(fprov.cache_params())
        fparams["seed"] = seed
        if (cfg.get("features", {}) or {}).get("provider") == "openclip":
            fparams["model_files"] = _folder_signature(cfg["features"].get("checkpoint"))
        if isinstance(fprov, TextAlignedFeatures) and not scene.has_instances and L.label_source(scene):
            fparams["labels"] = L.label_digest(scene, views)   # the classes it names masks by
        fkey = cache_key("features", fprov.id, PIPELINE_VERSION, fparams, {"masks": mkey})
        hit = cache.load("features", fkey)
        if hit is not None:
            arrays, _ = hit
            mask_features = {}
            for k, vec in arrays.items():
                _, v, t = k.split("_")
                mask_features[(int(v), int(t))] = vec.astype(np.float32)
        else:
            mask_features = {}
            for v in tqdm(views, desc=f"mask features ({fprov.id})", disable=not progress, leave=False):
                img = images[v] if fprov.needs_image else None
                for t, vec in fprov.encode_masks(scene, v, img, masks[v], seed).items():
                    mask_features[(v, int(t))] = vec
            cache.save("features", fkey, {f"f_{v}_{t}": vec for (v, t), vec in mask_features.items()},
                       {"provider": fprov.id})
        cache_info["features"] = {"key": fkey, "hit": hit is not None}
        providers["features"] = fprov.id
        if bool((cfg.get("features", {}) or {}).get("per_track", False)):
            if per_frame_masks:
                skipped["features.per_track"] = "per-frame masks have no tracks across views"
            else:
                mask_features = track_mean_features(mask_features)
                providers["features"] = fprov.id + "+track-mean"
        bar.update(1)
    else:
        skipped["features"] = "not needed by the method"
    bar.close()

    return Priors(order=order, depth=depth, masks=masks if (need_masks or need_features) else None,
                  mask_features=mask_features, feature_provider=fprov, providers=providers,
                  skipped=skipped, stats=stats, cache=cache_info)


def track_mean_features(features: Mapping[tuple[int, int], np.ndarray]) -> dict[tuple[int, int], np.ndarray]:
    """Every (view, track) gets the renormalised mean of the track's features over its views."""
    sums: dict[int, np.ndarray] = {}
    for (_, t), f in features.items():
        sums[t] = sums.get(t, 0.0) + np.asarray(f, dtype=np.float64)
    means = {}
    for t, f in sums.items():
        n = float(np.linalg.norm(f))
        # opposite unit vectors can cancel: keep the zero rather than divide by it
        means[t] = (f / n if n > 1e-12 else f).astype(np.float32)
    return {(v, t): means[t] for (v, t) in features}


def default_cache_dir(runs_parent: str | os.PathLike) -> Path:
    """The default cache folder for `priors.cache_dir: null`: <runs parent>/.gsbench_cache."""
    return Path(runs_parent) / rundir.CACHE_DIRNAME
