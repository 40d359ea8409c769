"""PSNR and SSIM: hand-computed values, agreement with scikit-image (valid form) and with the 3DGS
formula re-typed independently (zero-padded form, the default)."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
import torch
import torch.nn.functional as F
from paths import SHARED_DATA
from skimage.metrics import structural_similarity as sk_ssim

from gsbench.errors import InputError
from gsbench.metrics import METRIC_IMPL, PSNR_IMPL, SSIM_IMPL, psnr, ssim, ssim_map

SHARED = SHARED_DATA / "kaolin_clock" / "views"
# Measured: |ours(valid) - skimage| <= 2.2e-16 on every image below (float64); the bound leaves room
# for BLAS / filter summation-order differences on other machines.
SSIM_TOL = 1e-9


def _skimage(a, b):
    return sk_ssim(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1,
                   channel_axis=-1 if a.ndim == 3 else None)


def _natural_like(h, w, seed):
    """Smooth shading, hard edges and fine texture: the statistics of a rendered scene."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    img = np.stack([0.5 + 0.3 * np.sin(6 * x + c) * np.cos(4 * y - c) for c in range(3)], -1)
    img[(x - 0.5) ** 2 + (y - 0.4) ** 2 < 0.05] = [0.9, 0.2, 0.1]
    img[int(0.7 * h):, : int(0.3 * w)] = 0.05
    img += 0.03 * rng.standard_normal(img.shape)
    return np.clip(img, 0, 1)


def test_psnr_hand_values():
    gt = np.zeros((4, 4, 3))
    pred = np.full((4, 4, 3), 0.1)
    assert psnr(pred, gt, quantize=False) == pytest.approx(20.0, abs=1e-9)      # MSE 0.01
    # quantised: 0.1 * 255 = 25.5 rounds half up to 26
    assert psnr(pred, gt) == pytest.approx(20 * math.log10(255 / 26), abs=1e-9)


def test_psnr_identical_capped_and_clipping():
    a = np.random.default_rng(0).random((8, 8, 3))
    assert psnr(a, a) == pytest.approx(100.0)
    assert psnr(a, a, quantize=False) == pytest.approx(100.0)
    # values above 1 are clipped before the comparison
    assert psnr(np.full((4, 4), 1.7), np.ones((4, 4)), quantize=False) == pytest.approx(100.0)


def test_psnr_masked_hand():
    gt = np.zeros((2, 2))
    pred = np.array([[0.1, 0.5], [0.1, 0.1]])
    keep = np.array([[True, False], [True, True]])   # the 0.5 pixel is left out: MSE 0.01
    assert psnr(pred, gt, quantize=False, mask=keep) == pytest.approx(20.0)
    with pytest.raises(InputError):
        psnr(pred, gt, mask=np.zeros((2, 2), bool))


def test_psnr_bad_input():
    with pytest.raises(InputError):
        psnr(np.zeros((4, 4)), np.zeros((4, 5)))
    bad = np.zeros((4, 4))
    bad[0, 0] = np.nan
    with pytest.raises(InputError):
        psnr(bad, np.zeros((4, 4)))
    with pytest.raises(InputError, match="channels last"):
        psnr(np.zeros((3, 16, 16)), np.zeros((3, 16, 16)))


@pytest.mark.parametrize("shape", [(64, 80, 3), (37, 41), (11, 11, 3), (96, 128, 1)])
def test_ssim_matches_skimage_random(shape):
    rng = np.random.default_rng(sum(shape))
    a = rng.random(shape)
    b = np.clip(a + 0.15 * rng.standard_normal(shape), 0, 1)
    assert abs(ssim(a, b, border="valid") - _skimage(a, b)) <= SSIM_TOL


def test_ssim_matches_skimage_natural_like():
    a = _natural_like(120, 160, 1)
    for b in (
        cv2.GaussianBlur(a, (5, 5), 1.2),
        np.clip(a + 0.05 * np.random.default_rng(2).standard_normal(a.shape), 0, 1),
        np.roll(a, 2, axis=1),
    ):
        assert abs(ssim(a, b, border="valid") - _skimage(a, b)) <= SSIM_TOL


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/kaolin_clock absent (fresh clone)")
def test_ssim_matches_skimage_real_views():
    a = cv2.imread(str(SHARED / "0_rgb.png"))[..., ::-1] / 255.0
    b = cv2.imread(str(SHARED / "1_rgb.png"))[..., ::-1] / 255.0
    assert abs(ssim(a, b, border="valid") - _skimage(a, b)) <= SSIM_TOL
    blurred = cv2.GaussianBlur(a, (7, 7), 2.0)
    assert abs(ssim(a, blurred, border="valid") - _skimage(a, blurred)) <= SSIM_TOL


def _ssim_zeropad_reference(a, b):
    """3DGS-style SSIM written independently with torch conv2d, zero padding 5."""
    g = torch.exp(-((torch.arange(11, dtype=torch.float64) - 5) ** 2) / (2 * 1.5 ** 2))
    g = g / g.sum()
    w = (g[:, None] @ g[None, :])[None, None]
    x = torch.from_numpy(a).permute(2, 0, 1)[:, None]
    y = torch.from_numpy(b).permute(2, 0, 1)[:, None]
    conv = lambda t: F.conv2d(t, w, padding=5)  # noqa: E731
    mx, my = conv(x), conv(y)
    sxx, syy, sxy = conv(x * x) - mx ** 2, conv(y * y) - my ** 2, conv(x * y) - mx * my
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    m = ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx ** 2 + my ** 2 + c1) * (sxx + syy + c2))
    return float(m.mean())


def test_ssim_zeropad_border_rule_explains_difference():
    a = _natural_like(48, 64, 3)
    b = cv2.GaussianBlur(a, (5, 5), 1.5)
    zp = ssim(a, b, border="zeropad")
    assert zp == pytest.approx(_ssim_zeropad_reference(a, b), abs=1e-10)
    # the two rules disagree overall ...
    assert abs(zp - _skimage(a, b)) > 1e-4
    # ... but only in the 5-px frame: the interior of the zero-padded map is the valid map
    full = ssim_map(a, b, border="zeropad")
    valid = ssim_map(a, b, border="valid")
    assert full.shape[:2] == (48, 64) and valid.shape[:2] == (38, 54)
    np.testing.assert_allclose(full[5:-5, 5:-5], valid, atol=1e-12)


def test_ssim_properties_and_errors():
    a = _natural_like(32, 32, 4)
    assert ssim(a, a) == pytest.approx(1.0, abs=1e-12)
    b = np.clip(a + 0.1, 0, 1)
    assert ssim(a, b) == pytest.approx(ssim(b, a), abs=1e-12)
    with pytest.raises(InputError):
        ssim(np.zeros((8, 8)), np.zeros((8, 8)), border="valid")        # smaller than the 11x11 window
    with pytest.raises(InputError):
        ssim(a, a, border="reflect")


def test_impl_ids():
    assert METRIC_IMPL["psnr"] == PSNR_IMPL[True] and "uint8" in PSNR_IMPL[True]
    assert METRIC_IMPL["ssim"] == SSIM_IMPL["zeropad"] and "zeropad-3dgs" in SSIM_IMPL["zeropad"]
    assert METRIC_IMPL["ssim_valid"] == SSIM_IMPL["valid"] and "valid" in SSIM_IMPL["valid"]


def _ssim_3dgs_scipy(a, b):
    """The 3DGS `ssim` re-typed in float64 with scipy: 2-D Gaussian window 11 / 1.5 as the outer
    product of the normalised 1-D taps exp(-(x - 5)^2 / 4.5), per-channel correlation with zero
    padding of 5 px (same-size output), C1 = 0.01^2, C2 = 0.03^2, mean over the whole map."""
    from scipy.ndimage import correlate
    t = np.array([math.exp(-((x - 5) ** 2) / (2 * 1.5 ** 2)) for x in range(11)])
    t /= t.sum()
    win = np.outer(t, t)
    a3 = a if a.ndim == 3 else a[..., None]
    b3 = b if b.ndim == 3 else b[..., None]
    vals = []
    for c in range(a3.shape[2]):
        x, y = a3[..., c].astype(np.float64), b3[..., c].astype(np.float64)
        f = lambda z: correlate(z, win, mode="constant", cval=0.0)  # noqa: E731
        mx, my = f(x), f(y)
        vx, vy, cxy = f(x * x) - mx * mx, f(y * y) - my * my, f(x * y) - mx * my
        vals.append(((2 * mx * my + 1e-4) * (2 * cxy + 9e-4)) / ((mx * mx + my * my + 1e-4) * (vx + vy + 9e-4)))
    return float(np.mean(np.stack(vals, -1)))


@pytest.mark.parametrize("shape", [(96, 128, 3), (48, 64, 3), (37, 41), (5, 7, 3)])
def test_default_ssim_is_the_3dgs_form(shape):
    rng = np.random.default_rng(len(shape) + shape[0])
    a = _natural_like(shape[0], shape[1], 3) if len(shape) == 3 else rng.random(shape)
    b = np.clip(a + 0.08 * rng.standard_normal(a.shape), 0, 1)
    ref = _ssim_3dgs_scipy(a, b)
    assert ssim(a, b) == pytest.approx(ref, abs=1e-10)
    assert ssim(a, b, border="zeropad") == pytest.approx(ref, abs=1e-10)


@pytest.mark.parametrize("shape", [(40, 52, 3), (9, 14, 1), (23, 17), (4, 3, 3)])
def test_zeropad_metric_map_is_the_training_ssim_map_borders_included(shape):
    """The metric's default form and the training loss (gsbench/train/losses.py, and through `losses.ssim` on
    the CPU gsbench/train/ssim_cpu.py) are one formula with one set of constants (metrics/ssim_definition.py):
    their per-pixel maps agree in float64 everywhere, the 5-px frame the zero padding reaches included
    (shapes below the window size are all frame)."""
    from gsbench.train import losses as L
    rng = np.random.default_rng(sum(shape))
    a = rng.random(shape)
    b = np.clip(a + 0.2 * rng.standard_normal(shape), 0, 1)
    want = ssim_map(a, b, border="zeropad")
    got = L.ssim_map(torch.from_numpy(a), torch.from_numpy(b))[0].permute(1, 2, 0).numpy()
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    r = 5
    frame = np.ones(want.shape[:2], bool)
    frame[r:-r, r:-r] = False
    np.testing.assert_allclose(got[frame], want[frame], rtol=0, atol=1e-12)
    assert float(L.ssim(torch.from_numpy(a), torch.from_numpy(b))) == pytest.approx(ssim(a, b), abs=1e-12)


def test_ssim_constants_and_window_are_the_one_definition():
    from gsbench.metrics import ssim_definition as D
    from gsbench.metrics.image import gaussian_window
    from gsbench.train import losses as L
    assert (D.SSIM_WINDOW, D.SSIM_SIGMA, D.SSIM_C1, D.SSIM_C2) == (11, 1.5, 0.01 ** 2, 0.03 ** 2)
    assert (L.SSIM_C1, L.SSIM_C2) == (D.SSIM_C1, D.SSIM_C2)
    # the training loss computes its taps with torch, the metric with numpy: the same taps to float64 precision
    for size, sigma in ((D.SSIM_WINDOW, D.SSIM_SIGMA), (7, 1.0), (13, 2.0)):
        np.testing.assert_allclose(L._gaussian_1d(size, sigma, "cpu", torch.float64).numpy(),
                                   gaussian_window(size, sigma), rtol=0, atol=1e-15)


def test_3dgs_form_reads_higher_than_the_valid_region():
    """The zero frame is shared by both images, so the 3DGS form reads above the valid-region mean
    (the docs said the opposite before): measured on 128x96 natural-like pairs at three noise levels."""
    for seed, sd in ((0, 0.02), (1, 0.08), (2, 0.2)):
        rng = np.random.default_rng(seed)
        a = _natural_like(96, 128, seed)
        b = np.clip(cv2.GaussianBlur(a, (5, 5), 1.0) + sd * rng.standard_normal(a.shape), 0, 1)
        assert ssim(a, b, border="zeropad") > ssim(a, b, border="valid")
