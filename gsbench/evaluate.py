"""Evaluation: a trained run -> results.json, and a folder of predicted masks -> results.json.

`evaluate_run(run_dir, protocol="auto")` renders the test views of a trained run at the training
resolution and computes everything the scene supports:
  - image metrics psnr / ssim / lpips (lpips is null without local VGG weights, and says so),
  - fps (metrics timer: warm-up, median render time of the test views),
  - 3D-OVS (argmax over classes; mIoU, mBIoU, pixel accuracy) and/or LERF-OVS (relevancy against
    the canonical negatives; mIoU, localization accuracy), each in both query modes: encode
    (paper) and decode (LangSplat); the un-suffixed names carry the configured `query.mode`,
  - object removal on scenes with removal GT (synthetic): for each class query whose class has
    one instance, remove it and compare with the GT render without it,
  - the ordering metrics of the run's priors (from train_summary.json).
Whatever cannot be computed is in `skipped` with the reason; its value is null, never invented.

`score_mask_folder(pred_dir, layout_dir, protocol)` scores another method's masks with the same
protocol code. Folder formats (README, Evaluation and ablation grids):
  3dovs: <pred>/<view>/<class>.png (255 = class) or <pred>/<view>.png (class index, 255 = none),
         <view> = the segmentations/<idx> folder name or the stem of the idx-th sorted image;
  lerf:  <pred>/<frame_stem>/<query>.png (non-zero = query), '/' in a query written as '_'.
A missing prediction counts as IoU 0 and is listed (count + names) in `missing`; never dropped.
"""
from __future__ import annotations

import math
import os
import platform
import resource
import socket
import time
from pathlib import Path
from typing import Any, Optional

import cv2
import numpy as np

from gsbench.errors import InputError
from gsbench.store import read_json, write_json_atomic

PROTOCOLS = ("auto", "lerf", "3dovs")
QUERY_MODES = ("encode", "decode")
REMOVAL_IMPL = "removal/residual-absdiff0.1+psnr-outside/v1"
REMOVAL_RESIDUAL_TAU = 0.1   # an object pixel is "residual" if mean |RGB - GT without object| > this
MASK_FOLDER_IMPL = "mask-folder/v1"


# ----------------------------------------------------------------------------- small helpers
def peak_rss_mb() -> float:
    """Peak resident memory of this process (Linux ru_maxrss is in KiB, macOS in bytes)."""
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r / (1024.0 * 1024.0) if platform.system() == "Darwin" else r / 1024.0


def gsbench_version() -> Optional[str]:
    """The installed gsbench distribution's version (None when it is not installed as a package)."""
    from importlib import metadata
    try:
        return metadata.version("gsbench")
    except metadata.PackageNotFoundError:
        return None


def git_sha() -> Optional[str]:
    """HEAD commit of the gsbench checkout this code runs from; None when the package folder is not in a
    git work tree of gsbench (e.g. a wheel install) or git is missing. Read-only (`git rev-parse`)."""
    import subprocess
    pkg = Path(__file__).resolve().parent
    try:
        top = subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=pkg, capture_output=True, text=True, timeout=5)
        if top.returncode != 0 or Path(top.stdout.strip()).resolve() != pkg.parent:
            return None   # not a checkout, or a checkout of something else that happens to contain the package
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=pkg, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    sha = head.stdout.strip()
    return sha if head.returncode == 0 and sha else None


def machine_info() -> dict:
    import torch
    return {"host": socket.gethostname(), "cpu": platform.processor() or platform.machine(),
            "cores": os.cpu_count(), "torch": torch.__version__, "torch_threads": torch.get_num_threads(),
            "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
            "python": platform.python_version(), "gsbench": gsbench_version(), "git_sha": git_sha()}


def _mean(values: list) -> Optional[float]:
    vals = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return float(np.mean(vals)) if vals else None


def eval_camera(camera, max_width: Optional[int]):
    """The camera at the training resolution (train.max_width, the rule training uses)."""
    from gsbench.methods.base import training_size
    w, h = training_size(camera, max_width)
    return camera if (w, h) == (camera.width, camera.height) else camera.resized(w, h)


def resize_image(img: np.ndarray, width: int, height: int) -> np.ndarray:
    if img.shape[1] == width and img.shape[0] == height:
        return img
    return cv2.resize(img.astype(np.float32), (width, height), interpolation=cv2.INTER_AREA)


def resize_nearest(a: np.ndarray, width: int, height: int) -> np.ndarray:
    if a.shape[1] == width and a.shape[0] == height:
        return a
    dtype = a.dtype
    src = a.astype(np.uint8) if dtype == bool else a
    if src.dtype == np.int64:
        src = src.astype(np.int32)
    out = cv2.resize(src, (width, height), interpolation=cv2.INTER_NEAREST)
    return out.astype(bool) if dtype == bool else out


def _np(x) -> np.ndarray:
    import torch
    if isinstance(x, torch.Tensor):
        return x.detach().float().cpu().numpy()
    return np.asarray(x)


# ----------------------------------------------------------------------------- run evaluation
def resolve_protocols(scene, protocol: str) -> tuple[list[str], dict]:
    """Which segmentation protocols to run; `auto` = every one the scene supports."""
    if protocol not in PROTOCOLS:
        raise InputError(f"--protocol must be one of {', '.join(PROTOCOLS)}, got {protocol!r}")
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


def evaluate_run(run_dir: str | os.PathLike, protocol: str = "auto", progress: bool = True) -> dict:
    """Evaluate a trained run and write run_dir/results.json (schema: gsbench.store docstring)."""
    import torch

    from gsbench.runs import load_run
    run_dir = Path(run_dir)
    t_start = time.time()
    method, config, scene = load_run(run_dir)
    metrics: dict[str, Any] = {}
    per_view: dict[str, list] = {}
    metric_impl: dict[str, str] = {}
    skipped: dict[str, str] = {}
    timings: dict[str, Any] = {}

    test_ids = list(scene.test_ids)
    if not test_ids:
        raise InputError(f"scene {scene.path}: no test views to evaluate")
    max_width = (config.get("train") or {}).get("max_width")
    cams = [eval_camera(scene.cameras[i], max_width) for i in test_ids]
    view_names = [scene.cameras[i].name or str(i) for i in test_ids]

    with torch.no_grad():
        _image_metrics(method, scene, test_ids, cams, config, metrics, per_view, metric_impl, skipped, progress)
        _fps(method, cams, config, metrics, metric_impl, timings, skipped)
        protocols, pskip = resolve_protocols(scene, protocol)
        skipped.update({f"segmentation_{k}": v for k, v in pskip.items()})
        mode = (config.get("query") or {}).get("mode", "encode")
        for p in protocols:
            fn = _seg_3dovs if p == "3dovs" else _seg_lerf
            fn(method, scene, test_ids, cams, config, mode, metrics, per_view, metric_impl, skipped)
        _removal(method, scene, test_ids, cams, config, metrics, per_view, metric_impl, skipped)
    _ordering(run_dir, metrics, metric_impl, skipped)

    summary = _read_optional(run_dir / "train_summary.json")
    train_status = _read_optional(run_dir / "status.json")
    timings["train_s"] = summary.get("train_s", summary.get("wall_s"))
    timings["eval_s"] = time.time() - t_start
    memory = {"peak_rss_mb": peak_rss_mb()}
    if "peak_rss_mb" in summary:
        memory["train_peak_rss_mb"] = summary["peak_rss_mb"]
    for k in ("peak_cuda_mb", "train_peak_cuda_mb"):
        if k in summary:
            memory[k] = summary[k]
    if torch.cuda.is_available():
        memory["eval_peak_cuda_mb"] = torch.cuda.max_memory_allocated() / 2**20
    state = train_status.get("state", "done")
    providers = {"depth": None, "masks": None, "features": None}
    try:
        providers.update({k: v for k, v in (method.provider_ids() or {}).items()})
    except AttributeError:
        skipped["providers"] = "method has no provider_ids()"
    scene_name = scene.name or Path(scene.path).name
    results = {
        "results_version": 1,
        "run_id": config.get("run_id", run_dir.name),
        "method": config.get("method"),
        "scene": scene_name,
        "scene_path": str(scene.path),
        "seed": config.get("seed"),
        "study": config.get("study") or _cell_field(run_dir, "study"),
        "grid": config.get("grid") or {},
        "config": config,
        "providers": providers,
        "backend": getattr(method, "backend", None) or config.get("backend"),
        "protocol": protocols[0] if protocols else None,
        "protocols": protocols,
        "query_mode": mode,
        "metric_impl": metric_impl,
        "metrics": metrics,
        "per_view": per_view,
        "view_names": view_names,
        "skipped": skipped,
        "timings": timings,
        "memory": memory,
        "machine": machine_info(),
        "status": state if state in ("done", "failed", "nonfinite") else "done",
        "dropped": config.get("dropped", {}),
    }
    write_json_atomic(run_dir / "results.json", results)
    return results


def _read_optional(path: Path) -> dict:
    return read_json(path) if path.exists() else {}


def _cell_field(run_dir: Path, key: str) -> Any:
    p = run_dir / "cell.json"
    return read_json(p).get(key) if p.exists() else None


def _image_metrics(method, scene, test_ids, cams, config, metrics, per_view, metric_impl, skipped, progress):
    from tqdm import tqdm

    from gsbench.metrics import image as MI
    from gsbench.metrics import perceptual as MP
    vals: dict[str, list] = {"psnr": [], "ssim": [], "lpips": []}
    lpips_reason, lpips_impl = None, None
    net = (config.get("eval") or {}).get("lpips_net", "vgg")
    for i, cam in tqdm(list(zip(test_ids, cams)), desc="eval views", disable=not progress):
        out = method.render(cam)
        pred = np.clip(_np(out.rgb), 0.0, 1.0)
        gt = resize_image(scene.image(i), cam.width, cam.height)
        vals["psnr"].append(MI.psnr(pred, gt))
        vals["ssim"].append(MI.ssim(pred, gt))
        if lpips_reason is None:
            try:
                r = MP.lpips(pred, gt, net=net)
            except InputError as e:     # e.g. image smaller than LPIPS's 32 px minimum
                lpips_reason = str(e)
                continue
            if r.value is None:
                lpips_reason = r.reason or "n/a (no LPIPS weights)"
            else:
                vals["lpips"].append(r.value)
                lpips_impl = r.impl
    for k, impl in (("psnr", MI.PSNR_IMPL[True]), ("ssim", MI.SSIM_IMPL["valid"])):
        per_view[k] = vals[k]
        metrics[k] = _mean(vals[k])
        metric_impl[k] = impl
    if lpips_reason is not None:
        metrics["lpips"] = None
        skipped["lpips"] = lpips_reason
    else:
        per_view["lpips"] = vals["lpips"]
        metrics["lpips"] = _mean(vals["lpips"])
        metric_impl["lpips"] = lpips_impl


def _fps(method, cams, config, metrics, metric_impl, timings, skipped):
    from gsbench.metrics import timing
    ev = config.get("eval") or {}
    state = {"k": 0}

    def render_next() -> None:   # cycles through the test views
        method.render(cams[state["k"] % len(cams)])
        state["k"] += 1

    res = timing.time_fps(render_next, warmup=int(ev.get("fps_warmup", 3)), repeats=int(ev.get("fps_repeats", 10)))
    metrics["fps"] = res["fps"]
    metric_impl["fps"] = res["impl"]
    timings["render_ms"] = res["median_ms"]
    timings["fps"] = res["fps"]
    timings["fps_sync"] = res["sync"]


def _text(method, texts: list[str], mode: str):
    t = method.embed_text(list(texts), mode)
    return None if t is None else _np(t)


def _features(method, cam, mode: str):
    f = method.semantic_features(cam, mode)
    return None if f is None else _np(f)


def _seg_3dovs(method, scene, test_ids, cams, config, mode, metrics, per_view, metric_impl, skipped,
               query_modes: tuple = QUERY_MODES):
    from gsbench.metrics import ovs3d
    ratio = float((config.get("eval") or {}).get("boundary_dilation_ratio", 0.02))
    classes = list(scene.class_names)
    for qm in query_modes:
        text = _text(method, classes, qm)
        if text is None:
            skipped[f"3dovs_{qm}"] = f"method {config.get('method')} has no semantic field"
            continue
        views, no_gt = [], []
        names = []
        for i, cam in zip(test_ids, cams):
            gt_masks = _class_masks(scene, i, classes)
            if gt_masks is None:
                no_gt.append(scene.cameras[i].name or str(i))
                continue
            feats = _features(method, cam, qm)
            pred = None if feats is None else ovs3d.ovs3d_predict(feats, text)
            views.append(ovs3d.Ovs3dView(scene.cameras[i].name or str(i), pred, gt_masks))
            names.append(scene.cameras[i].name or str(i))
        if no_gt:
            skipped["3dovs_views_without_gt"] = f"{len(no_gt)} test views have no segmentation: {no_gt}"
        if not views:
            skipped[f"3dovs_{qm}"] = "no test view has 3D-OVS segmentations"
            continue
        r = ovs3d.evaluate_ovs3d_scene(views, classes, missing="error", dilation_ratio=ratio)
        vals = {"miou_3dovs": r.miou, "mbiou_3dovs": r.mbiou, "pixel_acc_3dovs": r.pixel_acc}
        by_name = {v["view"]: v for v in r.per_view}
        all_names = [scene.cameras[i].name or str(i) for i in test_ids]
        pv = {name: [by_name[n][key] if n in by_name else None for n in all_names]
              for name, key in (("miou_3dovs", "miou"), ("mbiou_3dovs", "mbiou"), ("pixel_acc_3dovs", "pixel_acc"))}
        for name in vals:
            metrics[f"{name}_{qm}"] = vals[name]
            per_view[f"{name}_{qm}"] = pv[name]
            metric_impl[f"{name}_{qm}"] = r.impl
            if qm == mode:
                metrics[name], per_view[name], metric_impl[name] = vals[name], pv[name], r.impl
        if r.skipped:
            skipped[f"3dovs_{qm}_views"] = "; ".join(f"{s['view']}: {s['reason']}" for s in r.skipped)
    for name in ("miou_3dovs", "mbiou_3dovs", "pixel_acc_3dovs"):
        metrics.setdefault(name, None)


def segmentation_metrics(method, scene, view_ids: list[int], cams: list, config: dict) -> tuple[dict, dict]:
    """(metrics, skipped) of the segmentation protocols the scene supports, on the given views and cameras,
    in the configured query mode only: the same code as `evaluate_run`, for the trainer's periodic
    evaluation (metric names as in results.json: miou_3dovs, mbiou_3dovs, pixel_acc_3dovs, miou_lerf,
    loc_acc_lerf; null where not computable, with the reason in skipped)."""
    import torch
    mode = (config.get("query") or {}).get("mode", "encode")
    if mode not in QUERY_MODES:
        raise ValueError(f"query.mode must be one of {', '.join(QUERY_MODES)}, got {mode!r}")
    metrics: dict[str, Any] = {}
    skipped: dict[str, str] = {}
    protocols, pskip = resolve_protocols(scene, "auto")
    skipped.update({f"segmentation_{k}": v for k, v in pskip.items()})
    with torch.no_grad():
        for p in protocols:
            fn = _seg_3dovs if p == "3dovs" else _seg_lerf
            fn(method, scene, list(view_ids), list(cams), config, mode, metrics, {}, {}, skipped, query_modes=(mode,))
    return metrics, skipped


def _class_masks(scene, i: int, classes: list[str]) -> Optional[dict]:
    """{class: bool mask} of view i (the per-class masks keep pixels two classes claim), or None."""
    loader = getattr(scene, "class_masks_loader", None)
    if loader is not None:
        m = loader(i)
        return None if m is None else {c: np.asarray(v, bool) for c, v in m.items()}
    gt = scene.gt_classes(i)
    if gt is None:
        return None
    gt = np.asarray(gt)
    return {c: gt == k for k, c in enumerate(classes)}


def _seg_lerf(method, scene, test_ids, cams, config, mode, metrics, per_view, metric_impl, skipped,
              query_modes: tuple = QUERY_MODES):
    from gsbench.metrics import lerf
    unlabeled = [scene.cameras[i].name or str(i) for i in test_ids if scene.gt_labels(i) is None]
    for qm in query_modes:
        neg = _text(method, list(lerf.CANONICAL_NEGATIVES), qm)
        if neg is None:
            skipped[f"lerf_{qm}"] = f"method {config.get('method')} has no semantic field"
            continue
        pairs, view_of_pair, view_names = [], [], []
        for i, cam in zip(test_ids, cams):
            labels = scene.gt_labels(i)
            if labels is None:
                continue
            src = scene.cameras[i]
            masks, boxes = label_masks(labels, src.width, src.height, cam.width, cam.height)
            queries = list(masks)
            feats = _features(method, cam, qm)
            rel = None
            if feats is not None and queries:
                rel = lerf.lerf_relevancy(feats, _text(method, queries, qm), neg)
            name = src.name or str(i)
            view_names.append(name)
            for k, q in enumerate(queries):
                pairs.append(lerf.LerfPair(name, q, None if rel is None else rel[k], masks[q], boxes[q]))
                view_of_pair.append(name)
        if not pairs:
            skipped[f"lerf_{qm}"] = "no labelled (frame, query) pair among the test views"
            continue
        r = lerf.evaluate_lerf_scene(pairs, missing="error")
        by_view: dict[str, list] = {}
        for pp in r.per_pair:
            if pp["iou"] is not None:
                by_view.setdefault(pp["frame"], []).append(pp["iou"])
        view_iou = [_mean(by_view.get(n, [])) for n in (scene.cameras[i].name or str(i) for i in test_ids)]
        metrics[f"miou_lerf_{qm}"] = r.miou       # plain mean over all (frame, query) pairs
        per_view[f"miou_lerf_{qm}"] = view_iou
        metric_impl[f"miou_lerf_{qm}"] = r.impl
        if qm == mode:
            metrics["miou_lerf"], per_view["miou_lerf"], metric_impl["miou_lerf"] = r.miou, view_iou, r.impl
            metrics["loc_acc_lerf"], metric_impl["loc_acc_lerf"] = r.loc_acc, r.impl
        if r.skipped:
            skipped[f"lerf_{qm}_pairs"] = "; ".join(f"{s['frame']}/{s['query']}: {s['reason']}" for s in r.skipped)
    if unlabeled:
        skipped["lerf_unlabeled_views"] = f"{len(unlabeled)} test views have no label file: {unlabeled}"
    for name in ("miou_lerf", "loc_acc_lerf"):
        metrics.setdefault(name, None)


def label_masks(labels: list, src_w: int, src_h: int, width: int, height: int) -> tuple[dict, dict]:
    """LERF label objects (pixel coordinates of a src_w x src_h image) -> {query: (H, W) bool mask,
    objects of a category OR-ed} and {query: (K, 4) boxes or None}: polygons rasterised at the source
    resolution with the datasets reader (cv2.fillPoly, the protocol), resized NEAREST to width x height."""
    from gsbench.datasets.ovs import label_masks as rasterise
    sx, sy = width / float(src_w), height / float(src_h)
    masks = {q: resize_nearest(m, width, height) for q, m in rasterise(labels, src_h, src_w).items()}
    boxes: dict[str, list] = {q: [] for q in masks}
    for obj in labels:
        if obj.bbox is not None:
            x1, y1, x2, y2 = obj.bbox
            boxes[obj.category].append([x1 * sx, y1 * sy, x2 * sx, y2 * sy])
    return masks, {q: (np.asarray(v, np.float64) if v else None) for q, v in boxes.items()}


def read_label_file(path: Path) -> tuple[int, int, list]:
    """(width, height, label objects) of a LERF-OVS label file; the size comes from `info`."""
    from gsbench.datasets.ovs import read_lerf_label
    info, objs = read_lerf_label(path)
    try:
        w, h = int(info["width"]), int(info["height"])
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{path}: info.width / info.height missing or not integers") from None
    if w < 1 or h < 1:
        raise InputError(f"{path}: image size {w}x{h} is not positive")
    return w, h, objs


def _removal(method, scene, test_ids, cams, config, metrics, per_view, metric_impl, skipped):
    """For each class with exactly one instance: remove by its class query, render the test views and
    compare with the GT render without that instance."""
    from gsbench.metrics.image import quantize_uint8
    if not (scene.has_removal and scene.has_instances and scene.instance_classes):
        skipped["removal"] = "scene has no removal ground truth (synthetic scenes only)"
        metrics["removal_residual"] = metrics["removal_psnr_outside"] = None
        return
    if _text(method, ["object"], "encode") is None:
        skipped["removal"] = f"method {config.get('method')}: this run has no semantic field to select objects"
        metrics["removal_residual"] = metrics["removal_psnr_outside"] = None
        return
    by_class: dict = {}
    for inst, cls in scene.instance_classes.items():
        by_class.setdefault(cls if isinstance(cls, str) else int(cls), []).append(int(inst))
    threshold = float((config.get("removal") or {}).get("threshold", 0.9))
    residuals, psnrs, per_view_res = [], [], [[] for _ in test_ids]
    notes = {}
    for cls, insts in sorted(by_class.items(), key=lambda kv: str(kv[0])):
        name = cls if isinstance(cls, str) else scene.class_names[cls]
        if len(insts) != 1:
            notes[name] = f"{len(insts)} instances share the class; no GT render without all of them"
            continue
        removable = getattr(scene, "removable_instances", None)
        if removable is not None and insts[0] not in removable:
            notes[name] = "no GT render without this object"
            continue
        removed, n_pruned = method.remove(name, threshold)
        for k, (i, cam) in enumerate(zip(test_ids, cams)):
            gt_rm = scene.removed_image(i, insts[0])
            inst_map = scene.gt_instances(i)
            if gt_rm is None or inst_map is None:
                continue
            obj = resize_nearest(np.asarray(inst_map, np.int32) == insts[0], cam.width, cam.height)
            if not obj.any():
                continue   # object not visible in this view: nothing to measure
            gt_rm = resize_image(gt_rm, cam.width, cam.height)
            pred = np.clip(_np(removed.render(cam).rgb), 0.0, 1.0)
            diff = np.abs(pred - gt_rm).mean(axis=-1)
            res = float(np.count_nonzero(diff[obj] > REMOVAL_RESIDUAL_TAU)) / float(np.count_nonzero(obj))
            residuals.append(res)
            per_view_res[k].append(res)
            outside = ~obj
            if outside.any():
                mse = float(np.mean((quantize_uint8(pred)[outside] - quantize_uint8(gt_rm)[outside]) ** 2))
                psnrs.append(-10.0 * math.log10(max(mse, 1e-10)))
        notes[name] = f"pruned {n_pruned} Gaussians"
    skipped.update({f"removal_{k}": v for k, v in notes.items() if not v.startswith("pruned")})
    if not residuals:
        skipped["removal"] = "no single-instance class visible in the test views"
        metrics["removal_residual"] = metrics["removal_psnr_outside"] = None
        return
    metrics["removal_residual"] = _mean(residuals)
    metrics["removal_psnr_outside"] = _mean(psnrs)
    per_view["removal_residual"] = [_mean(v) for v in per_view_res]
    metric_impl["removal_residual"] = metric_impl["removal_psnr_outside"] = REMOVAL_IMPL


def _ordering(run_dir: Path, metrics, metric_impl, skipped):
    from gsbench.metrics import ordering as MO
    summary = _read_optional(run_dir / "train_summary.json")
    stats = (summary.get("info") or {}).get("priors_stats") or summary.get("priors_stats") or {}
    impls = {"ordering_adjacent_distance": MO.ORDERING_DISTANCE_IMPL,
             "ordering_adjacent_mask_iou": MO.ORDERING_MASK_IOU_IMPL}
    for k, impl in impls.items():
        if stats.get(k) is not None:
            metrics[k] = stats[k]
            metric_impl[k] = impl
        else:
            metrics[k] = None
            skipped[k] = "not in the run's priors stats (no masks/ordering prior for this method or scene)"


# ----------------------------------------------------------------------------- mask folders
def _read_mask(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(f"{path}: cannot read the image")
    if img.ndim == 3:
        img = img[..., 0]
    return img


def _query_file(query: str) -> str:
    return query.replace("/", "_") + ".png"


def score_mask_folder(pred_dir: str | os.PathLike, layout_dir: str | os.PathLike, protocol: str,
                      out_dir: Optional[str | os.PathLike] = None, dilation_ratio: float = 0.02) -> dict:
    """Score predicted masks against a LERF-OVS label folder or a 3D-OVS scene; writes
    out_dir/results.json (default: pred_dir/results.json). Missing predictions count as IoU 0."""
    pred_dir, layout_dir = Path(pred_dir), Path(layout_dir)
    if not pred_dir.is_dir():
        raise InputError(f"{pred_dir}: prediction folder not found")
    if not layout_dir.is_dir():
        raise InputError(f"{layout_dir}: layout folder not found")
    t0 = time.time()
    if protocol == "lerf":
        res = _score_lerf(pred_dir, layout_dir, dilation_ratio)
    elif protocol == "3dovs":
        res = _score_3dovs(pred_dir, layout_dir, dilation_ratio)
    else:
        raise InputError(f"mask scoring needs --protocol lerf or 3dovs, got {protocol!r}")
    res.update({"results_version": 1, "run_id": None, "method": "external", "scene": layout_dir.name,
                "scene_path": str(layout_dir), "predictions": str(pred_dir), "seed": None, "study": None,
                "grid": {}, "providers": {"depth": None, "masks": None, "features": None}, "backend": None,
                "protocol": protocol, "timings": {"eval_s": time.time() - t0},
                "memory": {"peak_rss_mb": peak_rss_mb()}, "machine": machine_info(), "status": "done",
                "missing_policy": "a missing prediction counts as IoU 0 (and BIoU 0) and is listed"})
    out = Path(out_dir) if out_dir is not None else pred_dir
    write_json_atomic(out / "results.json", res)
    return res


def _check_known_names(pred_dir: Path, known: set[str], what: str, source: Path) -> None:
    """A per-query / per-class prediction file (PRED/<view>/<name>.png) must name a known query / class:
    a typo would otherwise be ignored silently and its query scored as missing."""
    for f in sorted(pred_dir.glob("*/*.png")):
        if f.name not in known:
            names = ", ".join(sorted(k[:-4] for k in known))
            raise InputError(f"{f}: unknown {what} {f.stem!r} (not in {source}; known: {names})")


def _lerf_label_files(layout_dir: Path) -> list[Path]:
    files = sorted(layout_dir.glob("frame_*.json"))
    if not files:
        files = sorted(p for p in layout_dir.glob("*.json") if p.name != "results.json")
    if not files:
        raise InputError(f"{layout_dir}: no LERF-OVS label files (frame_*.json)")
    return files


def _score_lerf(pred_dir: Path, layout_dir: Path, ratio: float) -> dict:
    from gsbench.metrics import segmentation as M
    pairs, missing, view_names, view_miou = [], [], [], []
    resized = 0
    labels = [(lf, *read_label_file(lf)) for lf in _lerf_label_files(layout_dir)]
    _check_known_names(pred_dir, {_query_file(str(o.category)) for _, _, _, objs in labels for o in objs}, "query",
                       layout_dir)
    for lf, w, h, objects in labels:
        gt_masks, _ = label_masks(objects, w, h, w, h)
        view_names.append(lf.stem)
        ious = []
        for q, gt in gt_masks.items():
            pf = pred_dir / lf.stem / _query_file(q)
            if not pf.exists():
                missing.append(f"{lf.stem}/{_query_file(q)}")
                pairs.append({"view": lf.stem, "query": q, "iou": 0.0, "biou": 0.0, "missing": True})
                ious.append(0.0)
                continue
            pred = _read_mask(pf) != 0
            if pred.shape != gt.shape:
                gt = resize_nearest(gt, pred.shape[1], pred.shape[0])
                resized += 1
            iou = M.iou(pred, gt, empty=1.0)
            biou = M.boundary_iou(pred, gt, dilation_ratio=ratio, empty=1.0)
            pairs.append({"view": lf.stem, "query": q, "iou": iou, "biou": biou, "missing": False})
            ious.append(iou)
        view_miou.append(_mean(ious))
    all_iou = [p["iou"] for p in pairs]
    skipped = {"loc_acc_lerf": "needs relevancy maps, not binary masks"}
    if resized:
        skipped["note_resized_gt"] = f"GT of {resized} pairs resized (nearest) to the prediction resolution"
    return {"metrics": {"miou_lerf": _mean(all_iou), "mbiou_lerf": _mean([p["biou"] for p in pairs]),
                        "loc_acc_lerf": None},
            "per_view": {"miou_lerf": view_miou}, "view_names": view_names, "pairs": pairs,
            "missing": {"count": len(missing), "files": missing},
            "metric_impl": {"miou_lerf": f"{MASK_FOLDER_IMPL}+{M.IOU_IMPL}+lerf-labels",
                            "mbiou_lerf": f"{MASK_FOLDER_IMPL}+{M.BIOU_IMPL}"},
            "skipped": skipped}


def _score_3dovs(pred_dir: Path, layout_dir: Path, ratio: float) -> dict:
    from gsbench.metrics import segmentation as M
    seg = layout_dir / "segmentations"
    classes_txt = seg / "classes.txt"
    if not classes_txt.exists():
        raise InputError(f"{classes_txt}: not found (a 3D-OVS scene has segmentations/classes.txt)")
    classes = sorted(c.strip() for c in classes_txt.read_text(encoding="utf-8").splitlines() if c.strip())
    if not classes:
        raise InputError(f"{classes_txt}: no classes")
    _check_known_names(pred_dir, {f"{c}.png" for c in classes}, "class", classes_txt)
    images = sorted(p for p in (layout_dir / "images").glob("*") if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    views = sorted((d for d in seg.iterdir() if d.is_dir()), key=lambda d: (not d.name.isdigit(),
                   int(d.name) if d.name.isdigit() else 0, d.name))
    if not views:
        raise InputError(f"{seg}: no view folders segmentations/<idx>/")
    pairs, missing, view_names = [], [], []
    per = {"miou": [], "mbiou": [], "acc": []}
    acc_skip = None
    for vd in views:
        stems = [vd.name]
        if vd.name.isdigit() and int(vd.name) < len(images):
            stems.append(images[int(vd.name)].stem)
        gt = {}
        shape = None
        for c in classes:
            f = vd / f"{c}.png"
            if f.exists():
                gt[c] = _read_mask(f) == 255
                shape = gt[c].shape
        if shape is None:
            raise InputError(f"{vd}: no <class>.png masks")
        gt = {c: gt.get(c, np.zeros(shape, bool)) for c in classes}
        pred_masks, label_map = None, None
        for s in stems:
            if (pred_dir / s).is_dir():
                pred_masks = {c: (pred_dir / s / f"{c}.png") for c in classes}
                break
            if (pred_dir / f"{s}.png").exists():
                label_map = _read_mask(pred_dir / f"{s}.png").astype(np.int32)
                break
        view_names.append(vd.name)
        ious, bious = [], []
        if pred_masks is None and label_map is None:
            missing.append(f"{vd.name} (whole view)")
            for c in classes:
                pairs.append({"view": vd.name, "class": c, "iou": 0.0, "biou": 0.0, "missing": True})
            per["miou"].append(0.0)
            per["mbiou"].append(0.0)
            per["acc"].append(0.0)
            continue
        if label_map is not None:
            ph, pw = label_map.shape
            if label_map.max(initial=0) >= len(classes) and np.any((label_map >= len(classes)) & (label_map != 255)):
                raise InputError(f"{pred_dir / (stems[0] + '.png')}: class index >= {len(classes)} (255 = none)")
            cls_gt = np.full(shape, -1, np.int32)
            for k, c in enumerate(classes):
                cls_gt[gt[c]] = k
            cls_gt = resize_nearest(cls_gt, pw, ph)
            lab = cls_gt >= 0
            per["acc"].append(float(np.mean(label_map[lab] == cls_gt[lab])) if lab.any() else None)
        for k, c in enumerate(classes):
            if label_map is not None:
                p = label_map == k
            else:
                f = pred_masks[c]
                if not f.exists():
                    missing.append(f"{f.parent.name}/{f.name}")
                    pairs.append({"view": vd.name, "class": c, "iou": 0.0, "biou": 0.0, "missing": True})
                    ious.append(0.0)
                    bious.append(0.0)
                    continue
                p = _read_mask(f) == 255
            g = resize_nearest(gt[c], p.shape[1], p.shape[0])
            iou = M.iou(p, g, empty=0.0)
            biou = M.boundary_iou(p, g, dilation_ratio=ratio, empty=0.0)
            pairs.append({"view": vd.name, "class": c, "iou": iou, "biou": biou, "missing": False})
            ious.append(iou)
            bious.append(biou)
        if label_map is None:
            acc_skip = "per-class mask files do not define one class per pixel"
            per["acc"].append(None)
        per["miou"].append(_mean(ious))
        per["mbiou"].append(_mean(bious))
    skipped = {}
    if acc_skip:
        skipped["pixel_acc_3dovs"] = acc_skip
    return {"metrics": {"miou_3dovs": _mean([p["iou"] for p in pairs]),
                        "mbiou_3dovs": _mean([p["biou"] for p in pairs]),
                        "pixel_acc_3dovs": None if acc_skip else _mean(per["acc"])},
            "per_view": {"miou_3dovs": per["miou"], "mbiou_3dovs": per["mbiou"], "pixel_acc_3dovs": per["acc"]},
            "view_names": view_names, "pairs": pairs, "classes": classes,
            "missing": {"count": len(missing), "files": missing},
            "metric_impl": {"miou_3dovs": f"{MASK_FOLDER_IMPL}+{M.IOU_IMPL}+3dovs-empty0",
                            "mbiou_3dovs": f"{MASK_FOLDER_IMPL}+{M.BIOU_IMPL}+3dovs-empty0",
                            "pixel_acc_3dovs": f"{MASK_FOLDER_IMPL}+pixel-acc"},
            "skipped": skipped}
