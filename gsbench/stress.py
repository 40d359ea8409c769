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
        # 100k Gaussians covering the whole image (a cluster in the middle would leave the border
        # pixels unsaturated and make the reference walk all 100k per tile: minutes instead of seconds)
        add("100k Gaussians", lambda: _field(100_000, spread=2.0, log_scale=-3.5, opacity_logit=3.0),
            cam_fn=lambda: _camera(48, 48),
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
    return torch.as_tensor(np.asarray(x) if not isinstance(x, torch.Tensor) else x).to(dtype).clone().requires_grad_(True)


def _grads(loss: torch.Tensor, leaves: list[torch.Tensor]) -> list[torch.Tensor]:
    g = torch.autograd.grad(loss, leaves, allow_unused=True)
    return [torch.zeros_like(x) if gi is None else gi for x, gi in zip(leaves, g)]


# ---------------------------------------------------------------------------- projection
@register
def projection_cases() -> list[Case]:
    """project_gaussians in float32 against float64: same culling, means2d, 2D covariance, depths, gradients."""
    from gsbench.render.projection import project_gaussians

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

    def zq():
        p = _field(100)
        p["quats"][:] = 0.0
        return p
    add("zero quaternions", zq)
    add("1x1 image", lambda: _field(100), cam_fn=lambda: _camera(1, 1))
    add("100k Gaussians", lambda: _field(100_000, spread=1.5, log_scale=-4.5), cam_fn=lambda: _camera(48, 48))
    return cases


# ---------------------------------------------------------------------------- scale-shift depth solve
def _lstsq_reference(prior: np.ndarray, target: np.ndarray, valid: np.ndarray) -> tuple[float, float]:
    """Independent float64 reference: numpy lstsq on the design matrix [prior, 1] (columns scaled)."""
    x = np.asarray(prior, dtype=np.float64).reshape(-1)
    y = np.asarray(target, dtype=np.float64).reshape(-1)
    m = np.asarray(valid, dtype=bool).reshape(-1) & np.isfinite(x) & np.isfinite(y)
    x, y = x[m], y[m]
    cx = max(float(np.max(np.abs(x))), 1e-300)
    A = np.stack([x / cx, np.ones_like(x)], 1)
    (s, t), *_ = np.linalg.lstsq(A, y, rcond=None)
    return float(s) / cx, float(t)


def _depth_pair(h: int = 24, w: int = 32, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A smooth positive 'rendered depth' and a structured prior (depth-like with a step edge)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    depth = 2.0 + xx + 0.5 * yy + 0.05 * rng.standard_normal((h, w))
    depth[:, w // 2:] += 1.0
    prior = 0.4 * depth + 0.3 + 0.01 * rng.standard_normal((h, w))
    return depth, prior


@register
def depth_solve_cases() -> list[Case]:
    """solve_scale_shift (float32 inputs) vs numpy lstsq in float64; degenerate priors skip as documented."""
    from gsbench.methods.losses import depth_loss, solve_scale_shift

    comp = "depth-solve"

    def solvable(make, note: str = "") -> CaseResult:
        depth, prior, valid = make()
        p32, d32 = prior.astype(np.float32), depth.astype(np.float32)
        st = solve_scale_shift(p32, d32, valid)
        s_ref, t_ref = _lstsq_reference(p32, d32, valid)
        # the prediction s * prior + t on the valid pixels is the quantity the loss uses
        m = valid & np.isfinite(p32)
        pred = st.s * p32[m].astype(np.float64) + st.t
        ref = s_ref * p32[m].astype(np.float64) + t_ref
        r = CaseResult(comp, "")
        r.max_abs, r.max_rel = compare(pred, ref)
        err = scaled_err(pred, ref)
        # the loss path: float32 rendered depth with gradient, finite loss and gradient
        dl = _leaf(d32, torch.float32)
        term = depth_loss("scale_shift", dl, p32, valid, "depth")
        grads = _grads(term.loss, [dl]) if term.loss is not None else None
        r.finite_out = bool(st.ok) and all_finite(pred) and term.loss is not None and all_finite(term.loss)
        r.finite_grad = None if grads is None else all_finite(*grads)
        r.passed = bool(r.finite_out and r.finite_grad and err <= 1e-6)
        r.note = f"s={st.s:.4g} t={st.t:.4g} vs lstsq s={s_ref:.4g} t={t_ref:.4g}; fit err {err:.1e} (tol 1e-06)" + (
            f"; {note}" if note else "")
        return r

    def skipped(make, expect: str) -> CaseResult:
        """Degenerate prior: solve reports ok=False with the documented reason; L_depth skips, no NaN anywhere."""
        depth, prior, valid = make()
        st = solve_scale_shift(prior.astype(np.float32), depth.astype(np.float32), valid)
        dl = _leaf(depth.astype(np.float32), torch.float32)
        terms = {}
        finite = True
        for form in ("scale_shift", "minmax", "pearson", "raw_l1"):
            for kind in ("depth", "disparity"):
                t = depth_loss(form, dl, prior.astype(np.float32), valid, kind)
                terms[(form, kind)] = t
                if t.loss is not None:
                    g = _grads(t.loss, [dl])
                    finite = finite and all_finite(t.loss, *g)
        r = CaseResult(comp, "")
        r.finite_out = finite and all_finite(st.s, st.t)
        r.finite_grad = finite
        ss = terms[("scale_shift", "depth")]
        r.passed = bool(r.finite_out and not st.ok and expect in st.reason and not bool(ss.ok) and expect in ss.reason)
        r.note = f"skip: {st.reason!r} (expected '{expect}'); L_depth scale_shift skipped={not bool(ss.ok)}"
        return r

    def base(h=24, w=32):
        d, p = _depth_pair(h, w)
        return d, p, np.ones(d.shape, bool)

    def with_nan():
        d, p, v = base()
        p[::3, ::2] = np.nan
        return d, p, v

    def with_inf():
        d, p, v = base()
        p[1::4, :] = np.inf
        p[2::4, :5] = -np.inf
        return d, p, v

    def negative():
        d, p, v = base()
        return d, -p - 5.0, v

    def huge():
        d, p, v = base()
        return d * 1e6, p * 1e6, v

    def huge_offset():
        d, p, v = base()
        return d, p + 1e6, v       # tiny relative variation on a 1e6 offset (float32 keeps ~0.06 resolution)

    def constant():
        d, p, v = base()
        return d, np.full_like(p, 3.0), v

    def near_constant():
        d, p, v = base()
        return d, 3.0 + 1e-14 * p, v

    def all_nan():
        d, p, v = base()
        return d, np.full_like(p, np.nan), v

    def all_inf():
        d, p, v = base()
        return d, np.full_like(p, np.inf), v

    def all_invalid():
        d, p, v = base()
        return d, p, np.zeros_like(v)

    def few_valid():
        d, p, v = base()
        v[:] = False
        v[0, :9] = True
        return d, p, v

    def zero_prior():
        d, p, v = base()
        return d, np.zeros_like(p), v

    cases = [
        Case(comp, "regular prior", lambda: solvable(base)),
        Case(comp, "prior with NaN pixels", lambda: solvable(with_nan, "NaN pixels excluded")),
        Case(comp, "prior with +/-inf pixels", lambda: solvable(with_inf, "inf pixels excluded")),
        Case(comp, "negative prior", lambda: solvable(negative)),
        Case(comp, "huge magnitudes (1e6)", lambda: solvable(huge)),
        Case(comp, "1e6 offset, small variation", lambda: solvable(huge_offset)),
        Case(comp, "constant prior", lambda: skipped(constant, "constant")),
        Case(comp, "near-constant prior (1e-14)", lambda: skipped(near_constant, "constant")),
        Case(comp, "all-zero prior", lambda: skipped(zero_prior, "constant")),
        Case(comp, "all-NaN prior", lambda: skipped(all_nan, "valid pixels")),
        Case(comp, "all-inf prior", lambda: skipped(all_inf, "valid pixels")),
        Case(comp, "all-invalid prior", lambda: skipped(all_invalid, "valid pixels")),
        Case(comp, "9 valid pixels (< 10)", lambda: skipped(few_valid, "valid pixels")),
    ]
    return cases


# ---------------------------------------------------------------------------- losses
def _images(h: int = 24, w: int = 32, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    gt = rng.random((h, w, 3))
    pred = np.clip(gt + 0.1 * rng.standard_normal((h, w, 3)), 0.0, 1.0)
    return pred, gt


def _loss_case(comp: str, fn: Callable[..., Optional[torch.Tensor]], inputs: list, grad_mask: list[bool],
               out_tol: float = 1e-5, grad_tol: float = 1e-4, expect: Optional[float] = None,
               expect_tol: float = 1e-6, note: str = "") -> CaseResult:
    """fn(*tensors) in float32 and float64; optional hand-computed expected value of the float64 output."""
    res = {}
    for dt in (torch.float32, torch.float64):
        xs = [(_leaf(x, dt) if g else torch.as_tensor(np.asarray(x))) for x, g in zip(inputs, grad_mask)]
        xs = [x.to(dt) if (isinstance(x, torch.Tensor) and x.is_floating_point() and not x.requires_grad) else x for x in xs]
        out = fn(*xs)
        if out is None:
            res[dt] = (None, None)
            continue
        leaves = [x for x, g in zip(xs, grad_mask) if g]
        res[dt] = ([out], _grads(out, leaves))
    (o32, g32), (o64, g64) = res[torch.float32], res[torch.float64]
    if o32 is None or o64 is None:
        return CaseResult(comp, "", passed=False, note=f"loss returned None (float32 {o32 is None}, float64 {o64 is None})")
    extra_ok = True
    if expect is not None:
        v = float(o64[0].detach())
        extra_ok = abs(v - expect) <= expect_tol * max(1.0, abs(expect))
        note = (note + "; " if note else "") + f"value {v:.6g} vs hand-computed {expect:.6g}"
    return _result(comp, o32, o64, g32, g64, out_tol, grad_tol, note=note, extra_ok=extra_ok)


@register
def loss_cases() -> list[Case]:
    """Each training loss in float32 vs float64 on regular and extreme inputs (gradients included)."""
    from gsbench.methods.losses import (DEPTH_FORMULATIONS, depth_edges, depth_loss, ds_loss, reconstruction_loss,
                                        sem_loss, tv_loss)

    cases: list[Case] = []

    def add(comp, name, fn):
        cases.append(Case(comp, name, fn))

    # L_rec = 0.8 L1 + 0.2 (1 - SSIM)
    pred, gt = _images()
    add("loss:rec", "random images", lambda: _loss_case("loss:rec", reconstruction_loss, [pred, gt], [True, False]))
    c = np.full((24, 32, 3), 0.5)
    add("loss:rec", "identical constant images",
        lambda: _loss_case("loss:rec", reconstruction_loss, [c, c.copy()], [True, False], expect=0.0, expect_tol=1e-9,
                           grad_tol=1e-2, note="L1 = 0 and SSIM = 1 exactly; gradient ~0 (float32 noise < 1e-8)"))
    add("loss:rec", "constant vs constant (0.5 vs 0)",
        lambda: _loss_case("loss:rec", reconstruction_loss, [c, np.zeros_like(c)], [True, False], out_tol=1e-4))
    one = np.full((1, 1, 3), 0.3)
    add("loss:rec", "1x1 images", lambda: _loss_case("loss:rec", reconstruction_loss, [one, one * 0.5], [True, False],
                                                     out_tol=1e-4))
    add("loss:rec", "prediction far outside [0,1] (+-1e3)",
        lambda: _loss_case("loss:rec", reconstruction_loss, [(pred - 0.5) * 2e3, gt], [True, False], out_tol=1e-4))

    # L_depth per formulation
    depth, prior = _depth_pair()
    valid = np.ones(depth.shape, bool)
    for form in DEPTH_FORMULATIONS[1:]:
        for kind, pr in (("depth", prior), ("disparity", 1.0 / prior)):
            add("loss:depth", f"{form}, {kind} prior",
                lambda f=form, k=kind, pr=pr: _loss_case(
                    "loss:depth", lambda d, f=f, k=k, pr=pr: depth_loss(f, d, pr.astype(np.float32), valid, k).loss,
                    [depth], [True], out_tol=1e-3 if f == "pearson" else 1e-4, grad_tol=1e-3))
        zero_d = depth.copy()
        zero_d[:4] = 0.0          # no surface rendered there (1/D guarded, not used)
        add("loss:depth", f"{form}, disparity prior, zero rendered depth rows",
            lambda f=form, zd=zero_d: _loss_case(
                "loss:depth", lambda d, f=f: depth_loss(f, d, (1.0 / prior).astype(np.float32), valid, "disparity").loss,
                [zd], [True], out_tol=1e-3 if f == "pearson" else 1e-4, grad_tol=1e-3,
                note="pearson: 1 - corr cancels in float32 when corr ~ 1" if f == "pearson" else ""))

    # L_tv
    const = np.full((24, 32), 2.0)
    eps = 1e-6
    add("loss:tv", "zero gradient (constant depth)",
        lambda: _loss_case("loss:tv", lambda d: tv_loss(d, eps), [const], [True], expect=math.sqrt(eps),
                           expect_tol=1e-9, note="sqrt(eps) exactly, zero gradient"))
    add("loss:tv", "zero gradient, eps = 0",
        lambda: _loss_case("loss:tv", lambda d: tv_loss(d, 0.0), [const], [True], expect=0.0, expect_tol=1e-12,
                           note="sqrt(0): gradient must not be NaN"))
    add("loss:tv", "regular depth", lambda: _loss_case("loss:tv", lambda d: tv_loss(d, eps), [depth], [True]))
    add("loss:tv", "huge depth steps (1e6)",
        lambda: _loss_case("loss:tv", lambda d: tv_loss(d, eps), [depth * 1e6], [True], out_tol=1e-5))
    add("loss:tv", "1x1 depth", lambda: _loss_case("loss:tv", lambda d: tv_loss(d, eps), [np.full((1, 1), 3.0)], [True],
                                                  expect=0.0, expect_tol=1e-12))

    # L_sem and L_ds
    rng = np.random.default_rng(3)
    s_hat = rng.standard_normal((24, 32, 3))
    s_tgt = rng.standard_normal((24, 32, 3))
    has = np.ones((24, 32), bool)
    has[:, :8] = False
    full = np.ones((24, 32), bool)
    empty = np.zeros((24, 32), bool)
    sem_ref = float(np.abs(s_hat - s_tgt)[has].mean())

    def sem_fn(has_m):
        return lambda a, b: sem_loss(a, b, torch.as_tensor(has_m))

    def ds_fn(edges, has_m=has):
        return lambda a, b: ds_loss(a, b, torch.as_tensor(has_m), torch.as_tensor(edges))

    add("loss:sem", "partial targets", lambda: _loss_case("loss:sem", sem_fn(has), [s_hat, s_tgt], [True, False],
                                                         expect=sem_ref, note="mean |S_hat - S| over target pixels"))
    add("loss:sem", "huge latents (1e6)", lambda: _loss_case("loss:sem", sem_fn(has), [s_hat * 1e6, s_tgt], [True, False]))

    def no_target() -> CaseResult:
        out = sem_loss(torch.as_tensor(s_hat), torch.as_tensor(s_tgt), torch.as_tensor(empty))
        ds = ds_loss(torch.as_tensor(s_hat), torch.as_tensor(s_tgt), torch.as_tensor(empty), torch.as_tensor(full))
        ok = float(out) == 0.0 and float(ds) == 0.0
        return CaseResult("loss:sem", "", finite_out=all_finite(out, ds), passed=ok,
                          note=f"no pixel has a target: L_sem = {float(out):.3g}, L_ds = {float(ds):.3g} "
                               "(documented: 0; the method knows such views up front and counts the skip)")
    add("loss:sem", "no pixel has a target", no_target)
    add("loss:ds", "empty edge map", lambda: _loss_case("loss:ds", ds_fn(empty), [s_hat, s_tgt], [True, False],
                                                       expect=0.0, expect_tol=1e-12, note="zero loss, zero gradient"))
    add("loss:ds", "full edge map (equals L_sem)", lambda: _loss_case("loss:ds", ds_fn(full), [s_hat, s_tgt], [True, False],
                                                                     expect=sem_ref))

    def edges_case(values, valid_m, expect_empty: bool, what: str) -> Callable[[], CaseResult]:
        def run() -> CaseResult:
            e = depth_edges(values, valid_m)
            ok = e.dtype == bool and e.shape == values.shape and (not e.any() if expect_empty else bool(e.any()))
            ds = ds_loss(torch.as_tensor(s_hat, dtype=torch.float32), torch.as_tensor(s_tgt, dtype=torch.float32),
                         torch.as_tensor(has), torch.as_tensor(e))
            fin = ds is not None and all_finite(ds)
            return CaseResult("loss:ds", "", finite_out=fin, passed=bool(ok and fin),
                              note=f"E_d on {what}: {int(e.sum())} edge pixels (expected {'none' if expect_empty else 'some'})")
        return run

    add("loss:ds", "edges of a constant prior", edges_case(np.full((24, 32), 5.0), full, True, "a constant prior"))
    add("loss:ds", "edges of an all-invalid prior", edges_case(prior, empty, True, "an all-invalid prior"))
    add("loss:ds", "edges of an all-NaN prior", edges_case(np.full((24, 32), np.nan), full, True, "an all-NaN prior"))

    def nonfinite_blocks() -> CaseResult:
        """NaN / inf blocks count as invalid: edges only at the real depth step, none along the blocks."""
        yy, xx = np.mgrid[0:24, 0:32]
        p = 1.0 + 0.01 * xx + 0.005 * yy + (xx >= 16) * 1.0      # noise-free ramp with one step at x = 16
        p[:8, :8] = np.nan
        p[16:, 4:12] = np.inf
        e = depth_edges(p, full)
        at_step = e & (np.abs(xx - 15.5) <= 3)
        elsewhere = int((e & ~at_step).sum())
        ok = e.dtype == bool and int(at_step.sum()) > 0 and elsewhere == 0
        return CaseResult("loss:ds", "", finite_out=True, passed=ok,
                          note=f"E_d: {int(at_step.sum())} edge pixels at the step, {elsewhere} elsewhere "
                               f"(e.g. along the NaN/inf blocks; expected > 0 and 0)")

    add("loss:ds", "edges of a prior with NaN/inf blocks", nonfinite_blocks)
    add("loss:ds", "edges of a prior with a step", edges_case(prior, full, False, "a prior with a depth step"))
    add("loss:ds", "edges of a 1e6 prior with a step", edges_case(prior * 1e6 + 1e6, full, False, "a 1e6 prior"))
    return cases


# ---------------------------------------------------------------------------- stiff loss weights
@register
def stiff_lambda_cases() -> list[Case]:
    """The GaussianDS total loss on a real render with lambdas spanning 1e-4..1e4: finite and float32 ~ float64."""
    from gsbench.methods.losses import depth_edges, depth_loss, ds_loss, reconstruction_loss, sem_loss, tv_loss
    from gsbench.render import render

    cam = _camera(24, 24)
    rng = np.random.default_rng(5)
    gt = rng.random((24, 24, 3))
    tgt = rng.standard_normal((24, 24, 3))
    has = np.ones((24, 24), bool)
    has[:5] = False

    params = _field(60, log_scale=-1.8)
    with torch.no_grad():   # the prior is an input of training: one fixed array for both precisions
        d_ref = render(GaussianField(**params), cam, backend="torch").depth.numpy()
    yy, xx = np.mgrid[0:24, 0:24]
    prior = 0.5 * d_ref + 0.2 + 0.05 * np.sin(xx / 3.0) * np.cos(yy / 4.0)
    pv = d_ref > 1e-3
    edges = torch.as_tensor(depth_edges(prior, pv))

    def total(lams: dict, dtype) -> tuple[torch.Tensor, list[torch.Tensor]]:
        leaves = {k: (None if v is None else v.to(dtype).clone().requires_grad_(True)) for k, v in params.items()}
        out = render(GaussianField(**leaves), cam, backend="torch")
        t = torch.as_tensor(tgt, dtype=dtype)
        h = torch.as_tensor(has)
        L = reconstruction_loss(out.rgb, torch.as_tensor(gt, dtype=dtype))
        dt = depth_loss("scale_shift", out.depth, prior, pv, "depth")
        if dt.loss is not None:
            L = L + lams["depth"] * dt.loss
        L = L + lams["tv"] * tv_loss(out.depth, 1e-6)
        L = L + lams["sem"] * sem_loss(out.features, t, h) + lams["ds"] * ds_loss(out.features, t, h, edges)
        names = ["means", "log_scales", "quats", "opacity_logits", "colors", "features"]
        return L, _grads(L, [leaves[k] for k in names])

    def case(lams: dict) -> CaseResult:
        l32, g32 = total(lams, torch.float32)
        l64, g64 = total(lams, torch.float64)
        r = _result("stiff-lambdas", [l32], [l64], g32, g64, out_tol=1e-4, grad_tol=2e-3,
                    note="lambdas " + ",".join(f"{k}={v:g}" for k, v in lams.items()))
        return r

    cases = []
    for v in (1e-4, 1e-2, 1.0, 1e2, 1e4):
        lams = {"depth": v, "tv": v, "sem": v, "ds": v}
        cases.append(Case("stiff-lambdas", f"all lambdas {v:g}", lambda lams=lams: case(lams)))
    cases.append(Case("stiff-lambdas", "depth,sem 1e4 / tv,ds 1e-4",
                      lambda: case({"depth": 1e4, "tv": 1e-4, "sem": 1e4, "ds": 1e-4})))
    cases.append(Case("stiff-lambdas", "depth,sem 1e-4 / tv,ds 1e4",
                      lambda: case({"depth": 1e-4, "tv": 1e4, "sem": 1e-4, "ds": 1e4})))
    cases.append(Case("stiff-lambdas", "paper weights (0.01, 1.5, 5, 1)",
                      lambda: case({"depth": 0.01, "tv": 1.5, "sem": 5.0, "ds": 1.0})))
    return cases


# ---------------------------------------------------------------------------- autoencoder
@register
def autoencoder_cases() -> list[Case]:
    """The frozen feature autoencoder: finite, unit-norm latents and reconstructions, float32 ~ float64."""
    from gsbench.methods.autoencoder import FeatureAutoencoder

    def case(make_x: Callable[[], torch.Tensor], latent_dim: int = 3, tol: float = 1e-4) -> CaseResult:
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(0)
            ae = FeatureAutoencoder(512, latent_dim)
        ae64 = FeatureAutoencoder(512, latent_dim).double()
        ae64.load_state_dict({k: v.double() for k, v in ae.state_dict().items()})
        x = make_x()
        outs = {}
        for dt, model in ((torch.float32, ae), (torch.float64, ae64)):
            xx = x.to(dt).clone().requires_grad_(True)
            z = model.encode(xx)
            y = model.decode(z)
            g = torch.autograd.grad((z.sum() + (y * torch.linspace(-1, 1, y.shape[-1], dtype=dt)).sum()), xx)[0]
            outs[dt] = ([z, y], [g])
        (o32, g32), (o64, g64) = outs[torch.float32], outs[torch.float64]
        norms = torch.cat([o.detach().norm(dim=-1) for o in o32])
        unit = bool(torch.isfinite(norms).all()) and float((norms - 1).abs().max()) <= 1e-5
        r = _result("autoencoder", o32, o64, g32, g64, out_tol=tol, grad_tol=1e-2,
                    note=f"output norms in [{float(norms.min()):.6f}, {float(norms.max()):.6f}] (must be 1)",
                    extra_ok=unit)
        return r

    g = torch.Generator().manual_seed(4)

    def unit_rows(n=16):
        x = torch.randn(n, 512, generator=g, dtype=torch.float64)
        return x / x.norm(dim=-1, keepdim=True)

    cases = [Case("autoencoder", "unit-norm inputs (d=3)", lambda: case(unit_rows)),
             Case("autoencoder", "unit-norm inputs (d=32)", lambda: case(unit_rows, latent_dim=32)),
             Case("autoencoder", "zero inputs", lambda: case(lambda: torch.zeros(4, 512, dtype=torch.float64))),
             Case("autoencoder", "tiny inputs (1e-30)", lambda: case(lambda: unit_rows(4) * 1e-30))]
    for mag in (1e6, 1e20, 1e30):
        cases.append(Case("autoencoder", f"huge inputs ({mag:g})", lambda mag=mag: case(lambda: unit_rows(4) * mag)))
    return cases


# ---------------------------------------------------------------------------- metrics
@register
def metric_cases() -> list[Case]:
    """Metrics on degenerate inputs: hand-computed values, defined behaviour for tiny images, float32 ~ float64."""
    from gsbench.errors import InputError
    from gsbench import metrics as M

    comp = "metrics"

    def value_case(fn: Callable[[], float], expect: float, tol: float = 1e-9, what: str = "") -> Callable[[], CaseResult]:
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

    def prec_case(fn: Callable[[np.ndarray, np.ndarray], float], a: np.ndarray, b: np.ndarray, tol: float) -> Callable[[], CaseResult]:
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
        Case(comp, "psnr identical images (100 dB cap)", value_case(lambda: M.psnr(c5, c5), 100.0, what="MSE 0 -> cap")),
        Case(comp, "psnr identical, not quantised", value_case(lambda: M.psnr(img_a, img_a, quantize=False), 100.0)),
        Case(comp, "psnr constant images 0.5 vs 0", value_case(lambda: M.psnr(c5, np.zeros_like(c5)),
                                                               -10 * math.log10(q * q), 1e-9, "uint8 128/255")),
        Case(comp, "psnr 1x1 images", value_case(lambda: M.psnr(np.full((1, 1, 3), 1.0), np.zeros((1, 1, 3))), 0.0)),
        Case(comp, "psnr float32 vs float64", prec_case(lambda a, b: M.psnr(a, b, quantize=False), img_a, img_b, 1e-5)),
        Case(comp, "ssim identical constant images", value_case(lambda: M.ssim(np.full((16, 16, 3), 0.3), np.full((16, 16, 3), 0.3)),
                                                                1.0, 1e-9, "(2mu^2+C1)/(2mu^2+C1) = 1")),
        Case(comp, "ssim constant 0.5 vs 0 (valid)", value_case(
            lambda: M.ssim(c5, np.zeros_like(c5)), (0.01 ** 2) / (0.25 + 0.01 ** 2), 1e-6, "C1 / (mu^2 + C1), sigma = 0")),
        Case(comp, "ssim 1x1 images (valid border)", raises_case(lambda: M.ssim(np.full((1, 1, 3), .3), np.full((1, 1, 3), .3)),
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
            res.passed = bool(res.finite_out and r.shape == (6, 5) and res.max_abs <= 1e-6 and float(r.max() - r.min()) == 0.0)
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
