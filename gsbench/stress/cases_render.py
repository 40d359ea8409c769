"""Render and projection cases: every backend present (float32) against the float64 torch reference."""
from __future__ import annotations

import math
from typing import Iterable

import numpy as np
import torch

from gsbench.camera import Camera
from gsbench.gaussians import GaussianField
from gsbench.render import render
from gsbench.render.gsplat_ext import build_gsplat_extension, gsplat_status
from gsbench.render.projection import project_gaussians
from gsbench.stress.core import Case, CaseResult, _camera, _field, _grads, _result, _to_np, all_finite, compare


def _zero_quats(n: int) -> dict:
    """A field of n Gaussians whose quaternions are all zero (the renderer must not divide by |q|)."""
    p = _field(n)
    p["quats"][:] = 0.0
    return p


def available_backends() -> list[str]:
    names = ["torch"]
    try:
        import gsbench.render.cpu_backend  # lazy: optional (numba probe)  # noqa: F401
        names.append("cpu")
    except ImportError:
        pass
    if torch.cuda.is_available():
        if gsplat_status().usable:      # importable is not enough: its CUDA extension must load (or build)
            build_gsplat_extension()    # the one-time compile, announced, before any case is timed
            names.append("gsplat")
    return names


def _render_case(backend: str, params: dict, camera: Camera, out_tol: float = 1e-4, grad_tol: float = 1e-2,
                 check_grad: bool = True) -> CaseResult:
    """float32 render on `backend` vs float64 torch reference; gradients of a fixed weighted sum."""

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

        def add(name, params_fn, cam_fn=_camera, comp=comp, be=be, **kw):
            cases.append(Case(comp, name, lambda p=params_fn, c=cam_fn, kw=kw: _render_case(be, p(), c(), **kw)))

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

        add("zero quaternions", lambda: _zero_quats(30))
        add("1x1 image", lambda: _field(30), cam_fn=lambda: _camera(1, 1))
        add("single Gaussian", lambda: _field(1, spread=0.0, log_scale=-1.0))
        # 100k Gaussians covering the whole image (a cluster in the middle would leave the border
        # pixels unsaturated and make the reference walk all 100k per tile: minutes instead of seconds)
        add("100k Gaussians", lambda: _field(100_000, spread=2.0, log_scale=-3.5, opacity_logit=3.0),
            cam_fn=lambda: _camera(48, 48),
            out_tol=5e-4, check_grad=False)
    return cases



# ---------------------------------------------------------------------------- projection
def projection_cases() -> list[Case]:
    """project_gaussians in float32 against float64: same culling, means2d, 2D covariance, depths, gradients."""

    def case(params_fn, cam_fn=_camera, tol: float = 1e-4, grad_tol: float = 1e-3) -> CaseResult:
        params = params_fn()
        cam = cam_fn()
        res = {}
        for dt in (torch.float32, torch.float64):
            leaves = {k: (None if v is None else v.to(dt).clone().requires_grad_(True)) for k, v in params.items()}
            p = project_gaussians(GaussianField(**leaves), cam)
            g = torch.Generator().manual_seed(2)
            outs = [p.means2d[p.ids], p.cov2d, p.depths, p.conics]
            loss = sum((o * torch.rand(o.shape, generator=g, dtype=torch.float64).to(o)).sum() for o in outs[:3])
            names = ["means", "log_scales", "quats"]
            grads = _grads(loss, [leaves[k] for k in names]) if loss.requires_grad else [torch.zeros(1)] * 3
            res[dt] = (p.ids, outs, grads, p.radii)
        ids32, o32, g32, r32 = res[torch.float32]
        ids64, o64, g64, r64 = res[torch.float64]
        same_ids = ids32.shape == ids64.shape and bool((ids32 == ids64).all())
        if not same_ids:
            r = CaseResult("projection", "", passed=False,
                           note=f"culling differs: float32 keeps {ids32.numel()}, float64 keeps {ids64.numel()}")
            r.finite_out = all_finite(*o32)
            return r
        radius_diff = int((r32 - r64).abs().max()) if r32.numel() else 0
        return _result("projection", o32, o64, g32, g64, tol, grad_tol,
                       note=f"{ids32.numel()}/{r32.shape[0]} visible, radius diff {radius_diff}px",
                       extra_ok=radius_diff <= 1)

    cases = []

    def add(name, params_fn, **kw):
        cases.append(Case("projection", name, lambda p=params_fn, kw=kw: case(p, **kw)))

    for s in (1e-6, 1e-3, 1.0, 1e3):
        add(f"scale {s:g} x scene", lambda s=s: _field(200, log_scale=math.log(s)))

    def aspect():
        p = _field(100)
        p["log_scales"][:, 1] = p["log_scales"][:, 0] + math.log(1e-4)
        return p
    add("aspect ratio 1e4", aspect)

    def at_depth(z):
        def make():
            p = _field(50, spread=0.02)
            p["means"][:, 2] = z - 4.0
            p["means"][:, :2] *= abs(z)
            return p
        return make
    add("just in front of the near plane (z=0.0101)", at_depth(0.0101))
    add("just behind the near plane (z=0.0099)", at_depth(0.0099))
    add("behind the camera (z=-1)", at_depth(-1.0))

    add("zero quaternions", lambda: _zero_quats(100))
    add("1x1 image", lambda: _field(100), cam_fn=lambda: _camera(1, 1))
    add("100k Gaussians", lambda: _field(100_000, spread=1.5, log_scale=-4.5), cam_fn=lambda: _camera(48, 48))
    return cases

