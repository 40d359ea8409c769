"""Reconstruction metrics (PSNR, SSIM, LPIPS) on the held-out views, and the render FPS.

Like 3DGS's metrics script, all three are computed on the 8-bit values a saved render holds
(`quantize_uint8` of the render and of the GT); the ids say so. LPIPS's input range is
`eval.lpips_input` and is part of its id.
"""
from __future__ import annotations

import logging

import cv2
import numpy as np

from gsbench.errors import InputError

from .block import Block, to_numpy
from .frames import size_text, view_name

log = logging.getLogger(__name__)
QUANTIZED = "+uint8-input"


def resize_image(img: np.ndarray, width: int, height: int) -> np.ndarray:
    """A GT image at the evaluation size (area averaging, as training loads it)."""
    if img.shape[1] == width and img.shape[0] == height:
        return img
    return cv2.resize(img.astype(np.float32), (width, height), interpolation=cv2.INTER_AREA)


def image_metrics(method, scene, ids: list[int], cams: list, config: dict, progress: bool = False) -> Block:
    """PSNR / SSIM / LPIPS of the renders of views `ids` (cameras `cams`) against their images."""
    from tqdm import tqdm

    from gsbench.metrics import image as MI
    from gsbench.metrics import perceptual as MP
    out = Block()
    if not ids:
        out.skip(("psnr", "ssim", "lpips"), "no held-out view (train.holdout: none trains on every view)")
        return out
    ev = config.get("eval") or {}
    net = ev.get("lpips_net", "vgg")
    rng = ev.get("lpips_input", MP.LPIPS_DEFAULT_RANGE)
    if rng not in MP.LPIPS_RANGES:   # a config error, not a skip: checked before any render
        raise InputError(f"eval.lpips_input must be one of {', '.join(MP.LPIPS_RANGES)}, got {rng!r}")
    names = [view_name(scene, i) for i in ids]
    vals: dict[str, list] = {"psnr": [], "ssim": [], "lpips": []}
    lpips_reason, lpips_impl = None, None
    for i, cam in tqdm(list(zip(ids, cams)), desc="eval views", disable=not progress):
        pred = MI.quantize_uint8(np.clip(to_numpy(method.render(cam).rgb), 0.0, 1.0))
        gt = MI.quantize_uint8(resize_image(scene.image(i), cam.width, cam.height))
        vals["psnr"].append(MI.psnr(pred, gt))
        vals["ssim"].append(MI.ssim(pred, gt))
        if lpips_reason is None:
            try:
                r = MP.lpips(pred, gt, net=net, input_range=rng)
            except InputError as e:     # e.g. image smaller than LPIPS's 32 px minimum
                lpips_reason = str(e)
                continue
            if r.value is None:
                lpips_reason = r.reason or "n/a (no LPIPS weights)"
            else:
                vals["lpips"].append(r.value)
                lpips_impl = r.impl + QUANTIZED
    out.put_mean("psnr", vals["psnr"], MI.PSNR_IMPL[True], names)
    out.put_mean("ssim", vals["ssim"], MI.SSIM_IMPL["valid"] + QUANTIZED, names)
    if lpips_reason is not None:
        out.put("lpips", None, MP.lpips_impl(net, input_range=rng) + QUANTIZED, lpips_reason)
    else:
        out.put_mean("lpips", vals["lpips"], lpips_impl, names)
    out.frames["reconstruction"] = names
    out.resolution["reconstruction"] = size_text(cams)
    return out


def fps(method, cams: list, config: dict) -> Block:
    """Median render time of the given cameras after warm-up (CUDA synchronised when it is in use)."""
    from gsbench.metrics import timing
    out = Block()
    if not cams:
        out.skip(("fps",), "no camera to time")
        return out
    ev = config.get("eval") or {}
    state = {"k": 0}

    def render_next() -> None:   # cycles through the views
        method.render(cams[state["k"] % len(cams)])
        state["k"] += 1

    res = timing.time_fps(render_next, warmup=int(ev.get("fps_warmup", 3)), repeats=int(ev.get("fps_repeats", 10)),
                          device=getattr(method, "device", None))
    out.put("fps", res["fps"], res["impl"], "timer returned no value")
    out.timings.update(render_ms=res["median_ms"], fps=res["fps"], fps_sync=res["sync"])
    return out

