"""Shared pieces of the stress battery: case and result types, float32-vs-float64 comparison,
running one case, and the small synthetic inputs (camera, Gaussians, images, depth) the cases use.
"""
from __future__ import annotations

import math
import time
import traceback
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np
import torch

from gsbench.camera import Camera


@dataclass
class CaseResult:
    component: str
    case: str
    max_abs: Optional[float] = None
    max_rel: Optional[float] = None
    finite_out: Optional[bool] = None
    finite_grad: Optional[bool] = None
    passed: bool = False
    note: str = ""
    seconds: float = 0.0

    def row(self) -> dict:
        return {
            "component": self.component, "case": self.case,
            "max_abs": self.max_abs, "max_rel": self.max_rel,
            "finite_out": self.finite_out, "finite_grad": self.finite_grad,
            "pass": self.passed, "note": self.note, "seconds": round(self.seconds, 3),
        }


@dataclass
class Case:
    component: str
    name: str
    fn: Callable[[], CaseResult]
    tags: tuple = field(default_factory=tuple)


# ---------------------------------------------------------------------------- comparison helpers
def _to_np(x) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().double().numpy()
    return np.asarray(x, dtype=np.float64)


def compare(a, b) -> tuple[float, float]:
    """Max abs error and max relative error (relative to max(|b|, 1e-6) elementwise, scale-aware)."""
    a, b = _to_np(a), _to_np(b)
    if a.size == 0:
        return 0.0, 0.0
    diff = np.abs(a - b)
    denom = np.maximum(np.abs(b), 1e-6 * max(1.0, float(np.max(np.abs(b))) if b.size else 1.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = diff / denom
    return float(np.nanmax(diff)), float(np.nanmax(rel))


def all_finite(*xs) -> bool:
    for x in xs:
        if x is None:
            continue
        if isinstance(x, torch.Tensor):
            if not bool(torch.isfinite(x).all()):
                return False
        elif not np.all(np.isfinite(np.asarray(x, dtype=np.float64))):
            return False
    return True

# ---------------------------------------------------------------------------- synthetic inputs
def _camera(width: int = 32, height: int = 32, dist: float = 4.0, fov_px: Optional[float] = None) -> Camera:
    f = fov_px if fov_px is not None else 1.2 * max(width, height)
    K = np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1.0]])
    w2c = np.eye(4)
    w2c[2, 3] = dist
    return Camera(K, w2c, width, height, "stress")


def _field(n: int, seed: int = 0, spread: float = 0.6, log_scale: float = -2.5, opacity_logit: Optional[float] = None,
           feat_dim: int = 3) -> dict:
    g = torch.Generator().manual_seed(seed)
    means = (torch.rand(n, 3, generator=g, dtype=torch.float64) * 2 - 1) * spread
    return {
        "means": means,
        "log_scales": (torch.full((n, 3), log_scale, dtype=torch.float64)
                       + 0.3 * torch.randn(n, 3, generator=g, dtype=torch.float64)),
        "quats": torch.randn(n, 4, generator=g, dtype=torch.float64),
        "opacity_logits": (torch.randn(n, generator=g, dtype=torch.float64) if opacity_logit is None
                           else torch.full((n,), float(opacity_logit), dtype=torch.float64)),
        "colors": torch.rand(n, 3, generator=g, dtype=torch.float64),
        "features": torch.randn(n, feat_dim, generator=g, dtype=torch.float64) if feat_dim else None,
    }



def _depth_pair(h: int = 24, w: int = 32, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A smooth positive 'rendered depth' and a structured prior (depth-like with a step edge)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    depth = 2.0 + xx + 0.5 * yy + 0.05 * rng.standard_normal((h, w))
    depth[:, w // 2:] += 1.0
    prior = 0.4 * depth + 0.3 + 0.01 * rng.standard_normal((h, w))
    return depth, prior



def _images(h: int = 24, w: int = 32, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    gt = rng.random((h, w, 3))
    pred = np.clip(gt + 0.1 * rng.standard_normal((h, w, 3)), 0.0, 1.0)
    return pred, gt



# ---------------------------------------------------------------------------- running
def run_case(case: Case) -> CaseResult:
    t0 = time.perf_counter()
    try:
        r = case.fn()
    except Exception as e:  # a crash is a failed case, with the reason in the table
        r = CaseResult(case.component, case.name, passed=False,
                       note=f"crashed: {type(e).__name__}: {e}".splitlines()[0][:300])
        r.note += " | " + traceback.format_exc(limit=2).splitlines()[-1][:200]
    r.component = case.component
    r.case = case.name
    r.seconds = time.perf_counter() - t0
    return r


# ---------------------------------------------------------------------------- shared helpers of the extra cases
GRAD_FLOOR = 1e-6   # gradients below this magnitude (per element) count as zero when scaling errors
def scaled_err(a, b, floor: float = 1e-30) -> float:
    """max |a - b| / max(max |b|, floor): error relative to the reference's magnitude (one number).

    `floor` keeps an exactly-zero reference (e.g. the gradient at an optimum) from turning float32
    rounding noise into an infinite relative error."""
    a, b = _to_np(a), _to_np(b)
    if a.size == 0:
        return 0.0
    with np.errstate(invalid="ignore", over="ignore"):
        err = float(np.max(np.abs(a - b))) / max(float(np.max(np.abs(b))), floor)
    return err if math.isfinite(err) else math.inf   # NaN never compares as "small"


def _result(component: str, outs32: list, outs64: list, grads32: Optional[list], grads64: Optional[list],
            out_tol: float, grad_tol: float = 1e-3, note: str = "", extra_ok: bool = True) -> CaseResult:
    """Compare float32 outputs (and gradients) with float64 ones; pass needs finite values within tolerance.

    Outputs are compared with `compare` (max abs, max rel) and the tolerance applies to the error
    scaled by the reference's magnitude; gradients likewise (scaled error per tensor).
    """
    r = CaseResult(component, "")
    r.finite_out = all_finite(*outs32)
    errs = [compare(a, b) for a, b in zip(outs32, outs64)]
    r.max_abs = max((e[0] for e in errs), default=0.0)
    r.max_rel = max((e[1] for e in errs), default=0.0)
    out_err = max((scaled_err(a, b) for a, b in zip(outs32, outs64)), default=0.0)
    ok = bool(r.finite_out) and out_err <= out_tol and all_finite(*outs64)
    parts = [f"out err {out_err:.1e} (tol {out_tol:g})"]
    if grads32 is not None:
        r.finite_grad = all_finite(*grads32)
        gerr = max((scaled_err(a, b, GRAD_FLOOR) for a, b in zip(grads32, grads64) if a is not None and b is not None),
                   default=0.0)
        ok = ok and bool(r.finite_grad) and gerr <= grad_tol
        parts.append(f"grad err {gerr:.1e} (tol {grad_tol:g})")
    if note:
        parts.append(note)
    r.note = "; ".join(parts)
    r.passed = bool(ok and extra_ok)
    return r


def _leaf(x, dtype) -> torch.Tensor:
    t = x if isinstance(x, torch.Tensor) else torch.as_tensor(np.asarray(x))
    return t.to(dtype).clone().requires_grad_(True)


def _grads(loss: torch.Tensor, leaves: list[torch.Tensor]) -> list[torch.Tensor]:
    g = torch.autograd.grad(loss, leaves, allow_unused=True)
    return [torch.zeros_like(x) if gi is None else gi for x, gi in zip(leaves, g)]
