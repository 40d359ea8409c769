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
from typing import Callable, Mapping, Sequence, TypeVar

import numpy as np
from tqdm.auto import tqdm

from gsbench import rundir
from gsbench.config_keys import MASK_PROVIDERS, PROPAGATORS
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


@dataclass
class _Run:
    """What every prior stage of one `prepare_priors` call shares: its inputs, the cache, the images, and
    the providers / skipped / stats / cache records the stages fill in (in stage order)."""

    scene: object
    views: list[int]
    size: tuple[int, int]
    seed: int
    progress: bool
    device: str | None
    cache: PriorCache
    images: _Images
    providers: dict
    skipped: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    cache_info: dict = field(default_factory=dict)
    _content: dict | None = None

    def scene_content(self) -> dict:
        """The scene part of a cache key; hashed on first use only (a run with every prior skipped never hashes)."""
        if self._content is None:
            self._content = {"scene": scene_content_hash(self.scene), "views": sorted(self.views),
                             "size": list(self.size)}
        return self._content


_T = TypeVar("_T")


def _cached(run: _Run, part: str, key: str, load: Callable[[dict, dict], _T], compute: Callable[[], _T],
            save: Callable[[_T], tuple[dict, dict]]) -> _T:
    """The cache read / compute / cache write every prior kind (`part`) goes through: `load(arrays, meta)`
    rebuilds the value from a hit; on a miss `compute()` makes it and `save(value)` gives the (arrays, meta)
    to store. Records the key and whether it hit in `run.cache_info[part]`."""
    hit = run.cache.load(part, key)
    if hit is not None:
        value = load(*hit)
    else:
        value = compute()
        run.cache.save(part, key, *save(value))
    run.cache_info[part] = {"key": key, "hit": hit is not None}
    return value


def _order_stage(run: _Run, cfg: Mapping) -> list[int]:
    """The view order (priors.ordering) and its mean adjacent camera distance."""
    mode = cfg.get("ordering", "pose")
    if mode not in ORDERINGS:
        raise InputError(f"priors.ordering: unknown ordering {mode!r} (expected one of {', '.join(ORDERINGS)})")
    order = order_views(run.scene.cameras, run.views, mode, run.seed)
    run.providers["ordering"] = mode
    run.stats["ordering_adjacent_distance"] = MO.mean_adjacent_distance(camera_centers(run.scene.cameras, order),
                                                                        list(range(len(order))))
    return order


def _depth_save(depth: dict[int, D.DepthPrior], views: list[int]) -> tuple[dict, dict]:
    kinds = {p.kind for p in depth.values()}
    arrays = {}
    for v, p in depth.items():
        arrays[f"values_{v}"] = p.values
        arrays[f"valid_{v}"] = p.valid
    first = depth[views[0]]
    return arrays, {"kind": first.kind, "provider": first.provider, "kinds": sorted(kinds)}


def _depth_stage(run: _Run, cfg: Mapping) -> dict[int, D.DepthPrior] | None:
    """The depth prior (cached), with the depth-noise study's noise applied after the cache; None when
    `priors.depth.provider` is none."""
    asked = dict(cfg.get("depth", {}) or {})
    # `auto` computes (and caches) exactly what its resolved provider does; only the record says auto
    dcfg, why = D.resolved_depth_cfg(asked, run.scene)
    auto = "auto -> " if asked.get("provider") == "auto" else ""
    pid = D.depth_provider_id(dcfg)
    if pid is None:
        run.skipped["depth"] = why or "priors.depth.provider=none"
        return None
    scene, views, seed = run.scene, run.views, run.seed
    params = {k: v for k, v in dcfg.items() if k != "noise"}
    params["seed"] = seed
    params["model_files"] = (_folder_signature(dcfg.get("model_path"))
                             if dcfg.get("provider") == "depth-anything" else [])
    if dcfg.get("provider") == "sfm":   # the scene fingerprint leaves the points out
        params["points"] = points_digest(scene)
    key = cache_key("depth", pid, PIPELINE_VERSION, params, run.scene_content())
    depth = _cached(
        run, "depth", key,
        lambda arrays, meta: {v: D.DepthPrior(arrays[f"values_{v}"], arrays[f"valid_{v}"].astype(bool),
                                              meta["kind"], meta["provider"]) for v in views},
        lambda: D.compute_depth(scene, dcfg, views, run.size, seed, run.progress, device=run.device),
        lambda d: _depth_save(d, views))
    depth = D.apply_depth_noise(depth, dcfg.get("noise"), seed)
    run.providers["depth"] = auto + depth[views[0]].provider
    return depth


def _mask_stage(run: _Run, cfg: Mapping, order: list[int], per_frame_masks: bool
                ) -> tuple[dict[int, np.ndarray], str]:
    """The masks (cached), their track count, and the ordering study's adjacent mask IoUs (cached too:
    optical flow and depth warps over every view pair, keyed by the masks and the order). Returns the
    masks and their cache key (the features' key builds on it)."""
    scene, views, seed = run.scene, run.views, run.seed
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
    mkey = cache_key("masks", prov, PIPELINE_VERSION, params, run.scene_content())
    masks, mid = _cached(
        run, "masks", mkey,
        lambda arrays, meta: ({v: arrays[f"m_{v}"].astype(np.int32) for v in views}, meta["provider"]),
        lambda: _compute_masks(scene, mcfg, views, order, run.size, run.images, bool(per_frame_masks), seed,
                               run.progress, device=run.device),
        lambda mm: ({f"m_{v}": mm[0][v] for v in views}, {"provider": mm[1]}))
    run.providers["masks"] = mid
    ids = np.unique(np.concatenate([m[m >= 0].ravel() for m in masks.values()])) if masks else []
    run.stats["mask_tracks"] = int(len(ids))
    if from_labels:   # views without labels have no segment, hence no semantic target
        run.stats["mask_labelled_views"] = int(sum(bool((masks[v] >= 0).any()) for v in views))
    skey = cache_key("mask-stats", mid, PIPELINE_VERSION, {"order": list(order)}, {"masks": mkey})
    mstats, mskipped = _cached(
        run, "mask-stats", skey,
        lambda arrays, meta: (meta["stats"], meta["skipped"]),
        lambda: _mask_stats(scene, views, order, run.size, masks, run.images, per_frame_masks),
        lambda ss: ({}, {"stats": ss[0], "skipped": ss[1]}))
    run.stats.update(mstats)
    run.skipped.update(mskipped)
    return masks, mkey


def _load_features(arrays: Mapping[str, np.ndarray]) -> dict[tuple[int, int], np.ndarray]:
    mask_features = {}
    for k, vec in arrays.items():
        _, v, t = k.split("_")
        mask_features[(int(v), int(t))] = vec.astype(np.float32)
    return mask_features


def _encode_features(run: _Run, fprov: FeatureProvider, masks: dict[int, np.ndarray]
                     ) -> dict[tuple[int, int], np.ndarray]:
    mask_features = {}
    for v in tqdm(run.views, desc=f"mask features ({fprov.id})", disable=not run.progress, leave=False):
        img = run.images[v] if fprov.needs_image else None
        for t, vec in fprov.encode_masks(run.scene, v, img, masks[v], run.seed).items():
            mask_features[(v, int(t))] = vec
    return mask_features


def _feature_stage(run: _Run, cfg: Mapping, masks: dict[int, np.ndarray], mkey: str, per_frame_masks: bool
                   ) -> tuple[dict[tuple[int, int], np.ndarray], FeatureProvider]:
    """Per-(view, mask) features (cached, keyed by the masks' key), track-averaged when
    `priors.features.per_track` asks."""
    scene = run.scene
    fprov = get_feature_provider(dict(cfg.get("features", {}) or {}), device=run.device)
    fparams = dict(fprov.cache_params())
    fparams["seed"] = run.seed
    if (cfg.get("features", {}) or {}).get("provider") == "openclip":
        fparams["model_files"] = _folder_signature(cfg["features"].get("checkpoint"))
    if isinstance(fprov, TextAlignedFeatures) and not scene.has_instances and L.label_source(scene):
        fparams["labels"] = L.label_digest(scene, run.views)   # the classes it names masks by
    fkey = cache_key("features", fprov.id, PIPELINE_VERSION, fparams, {"masks": mkey})
    mask_features = _cached(
        run, "features", fkey,
        lambda arrays, meta: _load_features(arrays),
        lambda: _encode_features(run, fprov, masks),
        lambda mf: ({f"f_{v}_{t}": vec for (v, t), vec in mf.items()}, {"provider": fprov.id}))
    run.providers["features"] = fprov.id
    if bool((cfg.get("features", {}) or {}).get("per_track", False)):
        if per_frame_masks:
            run.skipped["features.per_track"] = "per-frame masks have no tracks across views"
        else:
            mask_features = track_mean_features(mask_features)
            run.providers["features"] = fprov.id + "+track-mean"
    return mask_features, fprov


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
    run = _Run(scene, views, size, seed, progress, device, cache, images=_Images(scene, size),
               providers={"depth": None, "masks": None, "features": None})
    stages = 1 + int(need_depth) + int(need_masks or need_features) + int(need_features)
    bar = tqdm(total=stages, desc="priors", disable=not progress)

    order = _order_stage(run, cfg)
    bar.update(1)

    depth = None
    if need_depth:
        depth = _depth_stage(run, cfg)
        bar.update(1)
    else:
        run.skipped["depth"] = "not needed by the method"

    masks = None
    mkey = None
    if need_masks or need_features:
        masks, mkey = _mask_stage(run, cfg, order, per_frame_masks)
        bar.update(1)
    else:
        run.skipped["masks"] = "not needed by the method"

    mask_features = None
    fprov = None
    if need_features:
        mask_features, fprov = _feature_stage(run, cfg, masks, mkey, per_frame_masks)
        bar.update(1)
    else:
        run.skipped["features"] = "not needed by the method"
    bar.close()

    return Priors(order=order, depth=depth, masks=masks if (need_masks or need_features) else None,
                  mask_features=mask_features, feature_provider=fprov, providers=run.providers,
                  skipped=run.skipped, stats=run.stats, cache=run.cache_info)


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
