"""Reconstruction metrics (PSNR, SSIM, LPIPS) on the held-out views, and the render FPS.

Like 3DGS's metrics script, all of them are computed on the 8-bit values a saved render holds
(`quantize_uint8` of the render and of the GT); the ids say so. The GT is brought to the render's
size as training loads it (PIL bicubic, `gsbench.resize.resize_rgb`).
`ssim` and `lpips` are the 3DGS forms that 3DGS-family papers report (zero-padded SSIM; LPIPS fed
the [0, 1] images); `ssim_valid` and `lpips_package` keep the valid-region SSIM and the LPIPS
package's [-1, 1] input convention. Each id names its form.
"""
from __future__ import annotations

import logging

import numpy as np

from gsbench.config import setting
from gsbench.errors import InputError
from gsbench.metrics import image as MI
from gsbench.metrics import perceptual as MP
from gsbench.metrics import timing
from gsbench.resize import resize_rgb

from .block import Block, to_numpy
from .frames import size_text, view_name

log = logging.getLogger(__name__)
QUANTIZED = "+uint8-input"
SSIM_FORMS = {"ssim": "zeropad", "ssim_valid": "valid"}
LPIPS_FORMS = {"lpips": "3dgs-[0,1]", "lpips_package": "lpips-[-1,1]"}


def image_metrics(method, scene, ids: list[int], cams: list, config: dict, progress: bool = False) -> Block:
    """PSNR / SSIM / LPIPS (both forms of each) of the renders of views `ids` (cameras `cams`)."""
    from tqdm import tqdm

    out = Block()
    names_all = ("psnr", *SSIM_FORMS, *LPIPS_FORMS)
    if not ids:
        out.skip(names_all, "no held-out view (train.holdout: none trains on every view)")
        return out
    net = setting(config, "eval.lpips_net")
    names = [view_name(scene, i) for i in ids]
    vals: dict[str, list] = {k: [] for k in names_all}
    lpips_reason = None
    lpips_impls: dict[str, str] = {}
    for i, cam in tqdm(list(zip(ids, cams)), desc="eval views", disable=not progress):
        pred = MI.quantize_uint8(np.clip(to_numpy(method.render(cam).rgb), 0.0, 1.0))
        gt = MI.quantize_uint8(resize_rgb(np.asarray(scene.image(i), np.float32), cam.width, cam.height))
        vals["psnr"].append(MI.psnr(pred, gt))
        for name, border in SSIM_FORMS.items():
            vals[name].append(MI.ssim(pred, gt, border=border))
        for name, rng in LPIPS_FORMS.items():
            if lpips_reason is not None:
                break
            try:
                r = MP.lpips(pred, gt, net=net, input_range=rng)
            except InputError as e:     # e.g. image smaller than LPIPS's 32 px minimum
                lpips_reason = str(e)
                break
            if r.value is None:
                lpips_reason = r.reason or "n/a (no LPIPS weights)"
            else:
                vals[name].append(r.value)
                lpips_impls[name] = r.impl + QUANTIZED
    out.put_mean("psnr", vals["psnr"], MI.PSNR_IMPL[True], names)
    for name, border in SSIM_FORMS.items():
        out.put_mean(name, vals[name], MI.SSIM_IMPL[border] + QUANTIZED, names)
    for name, rng in LPIPS_FORMS.items():
        if lpips_reason is not None:
            out.put(name, None, MP.lpips_impl(net, input_range=rng) + QUANTIZED, lpips_reason)
        else:
            out.put_mean(name, vals[name], lpips_impls[name], names)
    out.frames["reconstruction"] = names
    out.resolution["reconstruction"] = size_text(cams)
    return out


def fps(method, cams: list, config: dict) -> Block:
    """Median render time of the given cameras after warm-up (CUDA synchronised when it is in use)."""
    out = Block()
    if not cams:
        out.skip(("fps",), "no camera to time")
        return out
    state = {"k": 0}

    def render_next() -> None:   # cycles through the views
        method.render(cams[state["k"] % len(cams)])
        state["k"] += 1

    res = timing.time_fps(render_next, warmup=int(setting(config, "eval.fps_warmup")),
                          repeats=int(setting(config, "eval.fps_repeats")),
                          device=getattr(method, "device", None))
    out.put("fps", res["fps"], res["impl"], "timer returned no value")
    out.timings.update(render_ms=res["median_ms"], fps=res["fps"], fps_sync=res["sync"])
    return out

