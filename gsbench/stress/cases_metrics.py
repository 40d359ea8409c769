"""Metric cases: hand-computed values on degenerate inputs, defined behaviour for tiny images."""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from gsbench import metrics as M
from gsbench.errors import InputError
from gsbench.stress.core import Case, CaseResult, _result, all_finite


def metric_cases() -> list[Case]:
    """Metrics on degenerate inputs: hand-computed values, defined behaviour for tiny images, float32 ~ float64."""

    comp = "metrics"

    def value_case(fn: Callable[[], float], expect: float, tol: float = 1e-9,
                   what: str = "") -> Callable[[], CaseResult]:
        def run() -> CaseResult:
            v = fn()
            r = CaseResult(comp, "")
            r.finite_out = v is not None and all_finite(v)
            r.max_abs = abs(float(v) - expect) if r.finite_out else None
            r.max_rel = r.max_abs / max(abs(expect), 1e-12) if r.finite_out else None
            r.passed = bool(r.finite_out and r.max_abs <= tol * max(1.0, abs(expect)))
            r.note = f"{v} vs hand-computed {expect:.10g}" + (f" ({what})" if what else "")
            return r
        return run

    def raises_case(fn: Callable[[], object], what: str) -> Callable[[], CaseResult]:
        def run() -> CaseResult:
            try:
                v = fn()
            except InputError as e:
                return CaseResult(comp, "", finite_out=True, passed=True, note=f"defined: InputError '{e}'")
            return CaseResult(comp, "", finite_out=all_finite(v), passed=False,
                              note=f"expected InputError ({what}), got {v!r}")
        return run

    def prec_case(fn: Callable[[np.ndarray, np.ndarray], float], a: np.ndarray, b: np.ndarray,
                  tol: float) -> Callable[[], CaseResult]:
        def run() -> CaseResult:
            v32 = fn(a.astype(np.float32), b.astype(np.float32))
            v64 = fn(a.astype(np.float64), b.astype(np.float64))
            return _result(comp, [v32], [v64], None, None, tol, note=f"float32 {v32:.8g} vs float64 {v64:.8g}")
        return run

    c5 = np.full((16, 16, 3), 0.5)
    q = round(0.5 * 255) / 255.0        # psnr quantises to uint8 by default
    rng = np.random.default_rng(7)
    img_a, img_b = rng.random((32, 32, 3)), rng.random((32, 32, 3))
    z = np.zeros((12, 12), bool)
    o = np.ones((12, 12), bool)
    one = np.ones((1, 1), bool)
    cases = [
        Case(comp, "psnr identical images (100 dB cap)",
             value_case(lambda: M.psnr(c5, c5), 100.0, what="MSE 0 -> cap")),
        Case(comp, "psnr identical, not quantised", value_case(lambda: M.psnr(img_a, img_a, quantize=False), 100.0)),
        Case(comp, "psnr constant images 0.5 vs 0", value_case(lambda: M.psnr(c5, np.zeros_like(c5)),
                                                               -10 * math.log10(q * q), 1e-9, "uint8 128/255")),
        Case(comp, "psnr 1x1 images", value_case(lambda: M.psnr(np.full((1, 1, 3), 1.0), np.zeros((1, 1, 3))), 0.0)),
        Case(comp, "psnr float32 vs float64", prec_case(lambda a, b: M.psnr(a, b, quantize=False), img_a, img_b, 1e-5)),
        Case(comp, "ssim identical constant images", value_case(
            lambda: M.ssim(np.full((16, 16, 3), 0.3), np.full((16, 16, 3), 0.3)), 1.0, 1e-9,
            "(2mu^2+C1)/(2mu^2+C1) = 1")),
        Case(comp, "ssim constant 0.5 vs 0 (valid)", value_case(
            lambda: M.ssim(c5, np.zeros_like(c5), border="valid"), (0.01 ** 2) / (0.25 + 0.01 ** 2), 1e-6,
            "C1 / (mu^2 + C1), sigma = 0")),
        Case(comp, "ssim 1x1 images (valid border)", raises_case(
            lambda: M.ssim(np.full((1, 1, 3), .3), np.full((1, 1, 3), .3), border="valid"),
            "valid border needs >= 11x11")),
        Case(comp, "ssim 1x1 identical (zeropad border)", value_case(
            lambda: M.ssim(np.full((1, 1, 3), .3), np.full((1, 1, 3), .3), border="zeropad"), 1.0, 1e-9)),
        Case(comp, "ssim float32 vs float64", prec_case(lambda a, b: M.ssim(a, b), img_a, img_b, 1e-5)),
        Case(comp, "iou empty vs empty", value_case(lambda: M.iou(z, z), 1.0, what="documented empty-union value")),
        Case(comp, "iou full vs full", value_case(lambda: M.iou(o, o), 1.0)),
        Case(comp, "iou empty vs full", value_case(lambda: M.iou(z, o), 0.0)),
        Case(comp, "iou 1x1 masks", value_case(lambda: M.iou(one, one), 1.0)),
        Case(comp, "iou 1x1 disjoint", value_case(lambda: M.iou(one, ~one), 0.0)),
        Case(comp, "boundary iou empty vs empty", value_case(lambda: M.boundary_iou(z, z), 1.0)),
        Case(comp, "boundary iou full vs full", value_case(lambda: M.boundary_iou(o, o), 1.0)),
        Case(comp, "boundary iou empty vs full", value_case(lambda: M.boundary_iou(z, o), 0.0)),
        Case(comp, "boundary iou 1x1 masks", value_case(lambda: M.boundary_iou(one, one), 1.0)),
    ]

    # LERF relevancy: r = min_j sigmoid(10 (cos(f, q) - cos(f, n_j)))
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
            res = CaseResult(comp, "")
            res.finite_out = all_finite(r)
            res.max_abs = float(np.max(np.abs(r - expect)))
            res.max_rel = res.max_abs / expect
            res.passed = bool(res.finite_out and r.shape == (6, 5) and res.max_abs <= 1e-6
                              and float(r.max() - r.min()) == 0.0)
            res.note = (f"constant map {float(r.mean()):.10f} vs hand-computed {expect:.10f} ({what}; "
                        f"cosines in float32 by design, tol 1e-6)")
            return res
        return run

    cases += [
        Case(comp, "lerf relevancy, constant features", rel_const(1.0, rel_expect(f), "unit-normalised first")),
        Case(comp, "lerf relevancy, constant huge features (1e30)", rel_const(1e30, rel_expect(f), "scale-invariant")),
        Case(comp, "lerf relevancy, zero features", rel_const(0.0, 0.5, "zero feature -> relevancy 0.5")),
    ]
    return cases
