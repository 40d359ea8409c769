"""The numerical stress battery behind `gsbench stress`.

Each case builds an extreme input, runs one component in float32 (the precision training uses)
and compares it with the same computation in float64, checking that outputs and gradients are
finite. One row per case: component, case, max abs / relative error, finite outputs, finite
gradients, pass/fail. Components whose code is absent from this build are listed as skipped with
the reason, never as passed.
"""
from __future__ import annotations

import math
import time
import traceback
from dataclasses import dataclass, field
from typing import Callable, Iterable, Optional

import numpy as np
import torch

from gsbench.gaussians import GaussianField
from gsbench.scene import Camera


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


# ---------------------------------------------------------------------------- render cases
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
        "log_scales": torch.full((n, 3), log_scale, dtype=torch.float64) + 0.3 * torch.randn(n, 3, generator=g, dtype=torch.float64),
        "quats": torch.randn(n, 4, generator=g, dtype=torch.float64),
        "opacity_logits": (torch.randn(n, generator=g, dtype=torch.float64) if opacity_logit is None
                           else torch.full((n,), float(opacity_logit), dtype=torch.float64)),
        "colors": torch.rand(n, 3, generator=g, dtype=torch.float64),
        "features": torch.randn(n, feat_dim, generator=g, dtype=torch.float64) if feat_dim else None,
    }


def available_backends() -> list[str]:
    names = ["torch"]
    try:
        import gsbench.render.cpu_backend  # noqa: F401
        names.append("cpu")
    except ImportError:
        pass
    if torch.cuda.is_available():
        try:
            import gsplat  # noqa: F401
            names.append("gsplat")
        except ImportError:
            pass
    return names


def _render_case(backend: str, params: dict, camera: Camera, out_tol: float = 1e-4, grad_tol: float = 1e-2,
                 check_grad: bool = True) -> CaseResult:
    """float32 render on `backend` vs float64 torch reference; gradients of a fixed weighted sum."""
    from gsbench.render import render

    def run(dtype, be):
        device = "cuda" if be == "gsplat" else "cpu"
        leaves = {k: (None if v is None else v.to(device=device, dtype=dtype).clone().requires_grad_(check_grad))
                  for k, v in params.items()}
        f = GaussianField(**leaves)
        out = render(f, camera, backend=be)
        tensors = [out.rgb, out.depth, out.alpha] + ([out.features] if out.features is not None else [])
        grads = None
        if check_grad:
            g = torch.Generator().manual_seed(1)
            loss = sum((t * torch.rand(t.shape, generator=g, dtype=torch.float64).to(t)).sum() for t in tensors)
            loss.backward()
            grads = {k: (None if v is None else v.grad) for k, v in leaves.items()}
        return tensors, grads

    r = CaseResult("render:" + backend, "")
    out32, g32 = run(torch.float32, backend)
    out64, g64 = run(torch.float64, "torch")
    r.finite_out = all_finite(*out32)
    errs = [compare(a, b) for a, b in zip(out32, out64)]
    r.max_abs = max(e[0] for e in errs)
    r.max_rel = max(e[1] for e in errs)
    ok = r.finite_out and r.max_abs <= out_tol
    if check_grad:
        r.finite_grad = all_finite(*[v for v in g32.values() if v is not None])
        gerr = []
        for k, v in g32.items():
            if v is None or g64[k] is None:
                continue
            ref = _to_np(g64[k])
            scale = max(1e-8, float(np.max(np.abs(ref))))
            gerr.append(float(np.max(np.abs(_to_np(v) - ref))) / scale)
        grad_rel = max(gerr) if gerr else 0.0
        r.note = f"grad rel err {grad_rel:.2e} (tol {grad_tol:g}); out tol {out_tol:g}"
        ok = ok and r.finite_grad and grad_rel <= grad_tol
    else:
        r.note = f"out tol {out_tol:g}"
    r.passed = bool(ok)
    return r


def render_cases(backends: Iterable[str]) -> list[Case]:
    cases: list[Case] = []
    for be in backends:
        comp = "render:" + be

        def add(name, params_fn, cam_fn=_camera, **kw):
            cases.append(Case(comp, name, lambda be=be, p=params_fn, c=cam_fn, kw=kw: _render_case(be, p(), c(), **kw)))

        for s in (1e-6, 1e-3, 1.0, 1e3):
            # scale relative to the scene size (spread 0.6 -> size ~1)
            add(f"scale {s:g} x scene", lambda s=s: _field(40, log_scale=math.log(s)), out_tol=2e-4, grad_tol=5e-2)

        def aspect():
            p = _field(30)
            p["log_scales"][:, 0] = math.log(0.05)
            p["log_scales"][:, 1] = math.log(0.05e-4)
            p["log_scales"][:, 2] = math.log(0.05)
            return p
        add("aspect ratio 1e4", aspect, out_tol=2e-4, grad_tol=5e-2)

        def near(z):
            def make():
                p = _field(20, spread=0.02)
                p["means"][:, 2] = z - 4.0  # camera at z = -4 in world (w2c translates by +4)
                p["means"][:, :2] *= z
                return p
            return make
        add("on the near plane (z=0.01)", near(0.01))
        add("just in front of the near plane (z=0.0101)", near(0.0101))
        add("just behind the near plane (z=0.0099)", near(0.0099))
        add("behind the camera (z=-1)", near(-1.0))

        def border():
            p = _field(30)
            p["means"][:, 0] = torch.linspace(-2.0, 2.0, 30, dtype=torch.float64)  # through and beyond the image edge
            return p
        add("at and outside the image border", border)

        def far_outside():
            p = _field(30)
            p["means"][:, 0] += 1e4
            return p
        add("far outside the image", far_outside)
        add("opacity 0", lambda: _field(30, opacity_logit=-30.0))
        add("opacity 1", lambda: _field(30, opacity_logit=30.0), check_grad=False)

        def zero_quats():
            p = _field(30)
            p["quats"][:] = 0.0
            return p
        add("zero quaternions", zero_quats)
        add("1x1 image", lambda: _field(30), cam_fn=lambda: _camera(1, 1))
        add("single Gaussian", lambda: _field(1, spread=0.0, log_scale=-1.0))
        add("100k Gaussians", lambda: _field(100_000, log_scale=-4.5), cam_fn=lambda: _camera(48, 48),
            out_tol=5e-4, check_grad=False)
    return cases


# ---------------------------------------------------------------------------- running
def all_cases(components: Optional[list[str]] = None) -> tuple[list[Case], list[CaseResult]]:
    """Every case of this build, plus skipped rows for components whose code is absent."""
    cases = render_cases(available_backends())
    skipped: list[CaseResult] = []
    for loader in _EXTRA_CASE_LOADERS:
        try:
            cases.extend(loader())
        except ImportError as e:
            skipped.append(CaseResult(loader.__name__.replace("_cases", ""), "(all)", passed=False,
                                      note=f"skipped: component not importable ({e})"))
    if components:
        cases = [c for c in cases if any(c.component.startswith(p) for p in components)]
        skipped = [s for s in skipped if any(s.component.startswith(p) for p in components)]
    return cases, skipped


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


_EXTRA_CASE_LOADERS: list[Callable[[], list[Case]]] = []


def register(loader: Callable[[], list[Case]]) -> Callable[[], list[Case]]:
    _EXTRA_CASE_LOADERS.append(loader)
    return loader
