"""Image-quality metrics: PSNR and SSIM on [0, 1] images (docs/metrics.md).

Images are (H, W) or (H, W, C) arrays or tensors with values in [0, 1]; NaN/inf is an
InputError. Both images are clipped to [0, 1] first (renders can overshoot slightly; the 3DGS
evaluation clamps them too).

PSNR: -10 log10(MSE). Default `quantize=True`: both images are rounded to uint8 first,
q = floor(255 x + 0.5) / 255, which is what an evaluation that reads saved PNGs measures (3DGS,
NerfBaselines). Identical images have MSE 0: the MSE is floored at 1e-10, so PSNR is capped at
100 dB (JSON cannot store inf, and a finite cap keeps means over views meaningful).

SSIM: Gaussian window 11, sigma 1.5 (normalised to sum 1), K1 0.01, K2 0.03, data range 1,
population (not sample) covariances, mean over the map and the channels. Border rule:
  "zeropad" (default): zero-padded filtering over the full H x W map, the form of the 3DGS
            repository's `ssim` that 3DGS-family papers report. Near the border the window sees
            the same zeros in both images, content they share, so the 5-px frame looks more alike
            than the interior and the mean reads *higher* than "valid" (docs/protocols.md: measured).
  "valid":  the statistics only where the whole 11x11 window lies inside the image; the map is
            (H-10) x (W-10). This is exactly the region skimage averages (it filters with
            reflection and then crops 5 px), so it agrees with
            skimage.metrics.structural_similarity(gaussian_weights=True, sigma=1.5,
            use_sample_covariance=False, data_range=1) to floating-point precision.
The constants are the one SSIM definition (metrics/ssim_definition.py), shared with the training loss
(gsbench/train/losses.py, gsbench/train/ssim_cpu.py); its "zeropad" map is the training form's to float tolerance
(tests/metrics/test_metrics_image.py). It stays a separate code path because an evaluation number is
computed in float64 from clipped images (with the "valid" border as a second convention, and a
denominator floor of 1e-20 instead of the training forms' 1e-12), while the training forms work in
the images' dtype on their device with gradients.
"""
from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from gsbench.errors import InputError

from ._common import as_mask, finite_float, same_shape
from .ssim_definition import SSIM_BORDERS, SSIM_C1, SSIM_C2, SSIM_SIGMA, SSIM_WINDOW, SSIM_ZEROPAD

SSIM_DEFAULT_BORDER = SSIM_ZEROPAD   # the 3DGS form: what 3DGS-family papers report
SSIM_DEN_FLOOR = 1e-20               # float64 evaluation: far below C1 C2, never hit with the constants
PSNR_MSE_FLOOR = 1e-10  # caps PSNR at 100 dB for identical images

PSNR_IMPL = {True: "psnr/uint8-round/v1", False: "psnr/float/v1"}
SSIM_IMPL = {"valid": "ssim/gauss11-1.5/valid/v1", "zeropad": "ssim/gauss11-1.5/zeropad-3dgs/v1"}


def _image_pair(pred: Any, gt: Any) -> tuple[np.ndarray, np.ndarray]:
    a = finite_float(pred, "pred image")
    b = finite_float(gt, "gt image")
    if a.ndim not in (2, 3):
        raise InputError(f"pred image: expected (H, W) or (H, W, C), got shape {a.shape}")
    same_shape(a, b, "pred image", "gt image")
    if a.ndim == 3 and a.shape[2] not in (1, 3, 4):
        raise InputError(f"pred image: expected channels last (H, W, C) with C in 1, 3, 4, got shape {a.shape}")
    if a.size == 0:
        raise InputError(f"pred image: empty array of shape {a.shape}")
    if a.ndim == 2:
        a, b = a[..., None], b[..., None]
    return np.clip(a, 0.0, 1.0), np.clip(b, 0.0, 1.0)


def quantize_uint8(x: np.ndarray) -> np.ndarray:
    """floor(255 x + 0.5) / 255 for x in [0, 1]: the value a saved 8-bit PNG holds (halves
    round up, as in torchvision's save_image, which the 3DGS renderer uses)."""
    return np.floor(np.clip(x, 0.0, 1.0) * 255.0 + 0.5) / 255.0


def psnr(pred: Any, gt: Any, *, quantize: bool = True, mask: Any | None = None) -> float:
    """PSNR in dB of `pred` against `gt` (both [0, 1]); see the module docstring for the cap.

    mask: optional (H, W) selection; the MSE is then taken over the selected pixels only (e.g.
    PSNR outside a removed object). A mask that selects nothing is an InputError.
    """
    a, b = _image_pair(pred, gt)
    if quantize:
        a, b = quantize_uint8(a), quantize_uint8(b)
    sq = (a - b) ** 2
    if mask is not None:
        m = as_mask(mask, "psnr mask")
        if m.shape != a.shape[:2]:
            raise InputError(f"psnr mask has shape {m.shape}, images are {a.shape[:2]}")
        if not m.any():
            raise InputError("psnr mask selects no pixel")
        sq = sq[m]
    mse = float(np.mean(sq))
    return -10.0 * math.log10(max(mse, PSNR_MSE_FLOOR))


def gaussian_window(size: int = SSIM_WINDOW, sigma: float = SSIM_SIGMA) -> np.ndarray:
    """1-D Gaussian taps, normalised to sum 1 (the separable SSIM window)."""
    r = (size - 1) / 2.0
    x = np.arange(size, dtype=np.float64) - r
    g = np.exp(-(x ** 2) / (2.0 * sigma ** 2))
    return g / g.sum()


def _filter(img: np.ndarray, g: np.ndarray, border: str) -> np.ndarray:
    # Correlation with a symmetric kernel == convolution. In "valid" mode the border type is
    # irrelevant because only pixels whose window is fully inside are kept.
    bt = cv2.BORDER_CONSTANT if border == "zeropad" else cv2.BORDER_REFLECT
    return cv2.sepFilter2D(img, cv2.CV_64F, g, g, borderType=bt)


def ssim_map(pred: Any, gt: Any, *, border: str = SSIM_DEFAULT_BORDER) -> np.ndarray:
    """Per-pixel SSIM, shape (H', W', C): H' = H - 10 for "valid", H for "zeropad"."""
    if border not in SSIM_BORDERS:
        raise InputError(f"ssim border must be one of {SSIM_BORDERS}, got {border!r}")
    a, b = _image_pair(pred, gt)
    h, w, c = a.shape
    if border == "valid" and (h < SSIM_WINDOW or w < SSIM_WINDOW):
        raise InputError(f"ssim (valid border) needs images of at least {SSIM_WINDOW}x{SSIM_WINDOW}, got {w}x{h}")
    g = gaussian_window()
    r = SSIM_WINDOW // 2
    c1, c2 = SSIM_C1, SSIM_C2
    out = []
    for ch in range(c):
        x = np.ascontiguousarray(a[..., ch])
        y = np.ascontiguousarray(b[..., ch])
        mx, my = _filter(x, g, border), _filter(y, g, border)
        sxx = _filter(x * x, g, border) - mx * mx
        syy = _filter(y * y, g, border) - my * my
        sxy = _filter(x * y, g, border) - mx * my
        num = (2 * mx * my + c1) * (2 * sxy + c2)
        den = (mx * mx + my * my + c1) * (sxx + syy + c2)  # >= c1 * c2 > 0 up to rounding
        m = num / np.maximum(den, SSIM_DEN_FLOOR)
        if border == "valid":
            m = m[r:h - r, r:w - r]
        out.append(m)
    return np.stack(out, axis=-1)


def ssim(pred: Any, gt: Any, *, border: str = SSIM_DEFAULT_BORDER) -> float:
    """Mean SSIM over the map and the channels (see the module docstring for the border rule)."""
    return float(np.mean(ssim_map(pred, gt, border=border)))
