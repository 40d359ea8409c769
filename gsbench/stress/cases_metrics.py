"""Metric cases: hand-computed values on degenerate inputs, defined behaviour for tiny images."""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from gsbench import metrics as M
from gsbench.errors import InputError
from gsbench.stress.core import Case, CaseResult, _result, all_finite

_COMP = "metrics"


def _value_case(fn: Callable[[], float], expect: float, tol: float = 1e-9, what: str = "") -> Callable[[], CaseResult]:
    """A case passing when fn() is finite and within tol (relative above 1) of the hand-computed value."""
    def run() -> CaseResult:
        v = fn()
        r = CaseResult(_COMP, "")
        r.finite_out = v is not None and all_finite(v)
        r.max_abs = abs(float(v) - expect) if r.finite_out else None
        r.max_rel = r.max_abs / max(abs(expect), 1e-12) if r.finite_out else None
        r.passed = bool(r.finite_out and r.max_abs <= tol * max(1.0, abs(expect)))
        r.note = f"{v} vs hand-computed {expect:.10g}" + (f" ({what})" if what else "")
        return r
    return run


def _raises_case(fn: Callable[[], object], what: str) -> Callable[[], CaseResult]:
    """A case passing when fn() refuses its input with an InputError (defined behaviour, not a crash)."""
    def run() -> CaseResult:
        try:
            v = fn()
        except InputError as e:
            return CaseResult(_COMP, "", finite_out=True, passed=True, note=f"defined: InputError '{e}'")
        return CaseResult(_COMP, "", finite_out=all_finite(v), passed=False,
                          note=f"expected InputError ({what}), got {v!r}")
    return run


def _prec_case(fn: Callable[[np.ndarray, np.ndarray], float], a: np.ndarray, b: np.ndarray,
               tol: float) -> Callable[[], CaseResult]:
    """A case comparing fn on float32 inputs with fn on float64 ones."""
    def run() -> CaseResult:
        v32 = fn(a.astype(np.float32), b.astype(np.float32))
        v64 = fn(a.astype(np.float64), b.astype(np.float64))
        return _result(_COMP, [v32], [v64], None, None, tol, note=f"float32 {v32:.8g} vs float64 {v64:.8g}")
    return run


def _psnr_cases(c5: np.ndarray, img_a: np.ndarray, img_b: np.ndarray) -> list[Case]:
    """PSNR: the 100 dB cap at MSE 0, uint8 quantisation, 1x1 images, float32 ~ float64."""
    q = round(0.5 * 255) / 255.0        # psnr quantises to uint8 by default
    return [
        Case(_COMP, "psnr identical images (100 dB cap)",
             _value_case(lambda: M.psnr(c5, c5), 100.0, what="MSE 0 -> cap")),
        Case(_COMP, "psnr identical, not quantised", _value_case(lambda: M.psnr(img_a, img_a, quantize=False), 100.0)),
        Case(_COMP, "psnr constant images 0.5 vs 0", _value_case(lambda: M.psnr(c5, np.zeros_like(c5)),
                                                                 -10 * math.log10(q * q), 1e-9, "uint8 128/255")),
        Case(_COMP, "psnr 1x1 images",
             _value_case(lambda: M.psnr(np.full((1, 1, 3), 1.0), np.zeros((1, 1, 3))), 0.0)),
        Case(_COMP, "psnr float32 vs float64",
             _prec_case(lambda a, b: M.psnr(a, b, quantize=False), img_a, img_b, 1e-5)),
    ]


def _ssim_cases(c5: np.ndarray, img_a: np.ndarray, img_b: np.ndarray) -> list[Case]:
    """SSIM: constant images (sigma = 0), 1x1 images per border mode, float32 ~ float64."""
    return [
        Case(_COMP, "ssim identical constant images", _value_case(
            lambda: M.ssim(np.full((16, 16, 3), 0.3), np.full((16, 16, 3), 0.3)), 1.0, 1e-9,
            "(2mu^2+C1)/(2mu^2+C1) = 1")),
        Case(_COMP, "ssim constant 0.5 vs 0 (valid)", _value_case(
            lambda: M.ssim(c5, np.zeros_like(c5), border="valid"), (0.01 ** 2) / (0.25 + 0.01 ** 2), 1e-6,
            "C1 / (mu^2 + C1), sigma = 0")),
        Case(_COMP, "ssim 1x1 images (valid border)", _raises_case(
            lambda: M.ssim(np.full((1, 1, 3), .3), np.full((1, 1, 3), .3), border="valid"),
            "valid border needs >= 11x11")),
        Case(_COMP, "ssim 1x1 identical (zeropad border)", _value_case(
            lambda: M.ssim(np.full((1, 1, 3), .3), np.full((1, 1, 3), .3), border="zeropad"), 1.0, 1e-9)),
        Case(_COMP, "ssim float32 vs float64", _prec_case(lambda a, b: M.ssim(a, b), img_a, img_b, 1e-5)),
    ]


def _iou_cases() -> list[Case]:
    """Mask IoU and boundary IoU on empty, full and 1x1 masks (the documented empty-union value)."""
    z = np.zeros((12, 12), bool)
    o = np.ones((12, 12), bool)
    one = np.ones((1, 1), bool)
    return [
        Case(_COMP, "iou empty vs empty", _value_case(lambda: M.iou(z, z), 1.0, what="documented empty-union value")),
        Case(_COMP, "iou full vs full", _value_case(lambda: M.iou(o, o), 1.0)),
        Case(_COMP, "iou empty vs full", _value_case(lambda: M.iou(z, o), 0.0)),
        Case(_COMP, "iou 1x1 masks", _value_case(lambda: M.iou(one, one), 1.0)),
        Case(_COMP, "iou 1x1 disjoint", _value_case(lambda: M.iou(one, ~one), 0.0)),
        Case(_COMP, "boundary iou empty vs empty", _value_case(lambda: M.boundary_iou(z, z), 1.0)),
        Case(_COMP, "boundary iou full vs full", _value_case(lambda: M.boundary_iou(o, o), 1.0)),
        Case(_COMP, "boundary iou empty vs full", _value_case(lambda: M.boundary_iou(z, o), 0.0)),
        Case(_COMP, "boundary iou 1x1 masks", _value_case(lambda: M.boundary_iou(one, one), 1.0)),
    ]


def _lerf_cases() -> list[Case]:
    """LERF relevancy r = min_j sigmoid(10 (cos(f, q) - cos(f, n_j))) on constant, huge and zero features."""
    qv = np.array([1.0, 0.0, 0.0, 0.0])
    negs = np.array([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.6, 0.8, 0.0, 0.0]])
    f = np.array([0.5, 0.5, 0.5, 0.5])

    def rel_expect(feat):
        u = feat / np.linalg.norm(feat)
        a = u @ qv
        return float(min(1.0 / (1.0 + math.exp(-10.0 * (a - u @ n))) for n in negs))

    def rel_const(scale: float, expect: float, what: str):
        def run() -> CaseResult:
            feats = np.broadcast_to(f * scale, (6, 5, 4)).copy()
            r = M.lerf_relevancy(feats, qv, negs)
            res = CaseResult(_COMP, "")
            res.finite_out = all_finite(r)
            res.max_abs = float(np.max(np.abs(r - expect)))
            res.max_rel = res.max_abs / expect
            res.passed = bool(res.finite_out and r.shape == (6, 5) and res.max_abs <= 1e-6
                              and float(r.max() - r.min()) == 0.0)
            res.note = (f"constant map {float(r.mean()):.10f} vs hand-computed {expect:.10f} ({what}; "
                        f"cosines in float32 by design, tol 1e-6)")
            return res
        return run

    return [
        Case(_COMP, "lerf relevancy, constant features", rel_const(1.0, rel_expect(f), "unit-normalised first")),
        Case(_COMP, "lerf relevancy, constant huge features (1e30)", rel_const(1e30, rel_expect(f), "scale-invariant")),
        Case(_COMP, "lerf relevancy, zero features", rel_const(0.0, 0.5, "zero feature -> relevancy 0.5")),
    ]


def metric_cases() -> list[Case]:
    """Metrics on degenerate inputs: hand-computed values, defined behaviour for tiny images, float32 ~ float64."""
    c5 = np.full((16, 16, 3), 0.5)
    rng = np.random.default_rng(7)
    img_a, img_b = rng.random((32, 32, 3)), rng.random((32, 32, 3))
    return _psnr_cases(c5, img_a, img_b) + _ssim_cases(c5, img_a, img_b) + _iou_cases() + _lerf_cases()
