"""Scale-shift depth-solve cases: the closed-form solve against numpy lstsq, degenerate priors included."""
from __future__ import annotations

from typing import Callable

import numpy as np
import torch

from gsbench.stress.core import Case, CaseResult, _depth_pair, _grads, _leaf, all_finite, compare, scaled_err
from gsbench.train.losses import depth_loss, solve_scale_shift


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


_COMP = "depth-solve"


def _solvable_case(make: Callable[[], tuple[np.ndarray, np.ndarray, np.ndarray]], note: str = "") -> CaseResult:
    """A prior the solve must fit: s * prior + t within 1e-6 of lstsq's, and L_depth finite with its gradient."""
    depth, prior, valid = make()
    p32, d32 = prior.astype(np.float32), depth.astype(np.float32)
    st = solve_scale_shift(p32, d32, valid)
    s_ref, t_ref = _lstsq_reference(p32, d32, valid)
    # the prediction s * prior + t on the valid pixels is the quantity the loss uses
    m = valid & np.isfinite(p32)
    pred = st.s * p32[m].astype(np.float64) + st.t
    ref = s_ref * p32[m].astype(np.float64) + t_ref
    r = CaseResult(_COMP, "")
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


def _skipped_case(make: Callable[[], tuple[np.ndarray, np.ndarray, np.ndarray]], expect: str) -> CaseResult:
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
    r = CaseResult(_COMP, "")
    r.finite_out = finite and all_finite(st.s, st.t)
    r.finite_grad = finite
    ss = terms[("scale_shift", "depth")]
    r.passed = bool(r.finite_out and not st.ok and expect in st.reason and not bool(ss.ok) and expect in ss.reason)
    r.note = f"skip: {st.reason!r} (expected '{expect}'); L_depth scale_shift skipped={not bool(ss.ok)}"
    return r


# (rendered depth, prior, valid) inputs: a regular pair and its extreme variants
def _base(h=24, w=32):
    d, p = _depth_pair(h, w)
    return d, p, np.ones(d.shape, bool)


def _with_nan():
    d, p, v = _base()
    p[::3, ::2] = np.nan
    return d, p, v


def _with_inf():
    d, p, v = _base()
    p[1::4, :] = np.inf
    p[2::4, :5] = -np.inf
    return d, p, v


def _negative():
    d, p, v = _base()
    return d, -p - 5.0, v


def _huge():
    d, p, v = _base()
    return d * 1e6, p * 1e6, v


def _huge_offset():
    d, p, v = _base()
    return d, p + 1e6, v       # tiny relative variation on a 1e6 offset (float32 keeps ~0.06 resolution)


def _constant():
    d, p, v = _base()
    return d, np.full_like(p, 3.0), v


def _near_constant():
    d, p, v = _base()
    return d, 3.0 + 1e-14 * p, v


def _all_nan():
    d, p, v = _base()
    return d, np.full_like(p, np.nan), v


def _all_inf():
    d, p, v = _base()
    return d, np.full_like(p, np.inf), v


def _all_invalid():
    d, p, v = _base()
    return d, p, np.zeros_like(v)


def _few_valid():
    d, p, v = _base()
    v[:] = False
    v[0, :9] = True
    return d, p, v


def _zero_prior():
    d, p, v = _base()
    return d, np.zeros_like(p), v


def _solvable_cases() -> list[Case]:
    """Priors the solve must fit, extreme ones included (non-finite pixels are excluded, not fatal)."""
    return [
        Case(_COMP, "regular prior", lambda: _solvable_case(_base)),
        Case(_COMP, "prior with NaN pixels", lambda: _solvable_case(_with_nan, "NaN pixels excluded")),
        Case(_COMP, "prior with +/-inf pixels", lambda: _solvable_case(_with_inf, "inf pixels excluded")),
        Case(_COMP, "negative prior", lambda: _solvable_case(_negative)),
        Case(_COMP, "huge magnitudes (1e6)", lambda: _solvable_case(_huge)),
        Case(_COMP, "1e6 offset, small variation", lambda: _solvable_case(_huge_offset)),
    ]


def _degenerate_cases() -> list[Case]:
    """Priors with no scale to fit (constant) or too few valid pixels: the solve must skip with its reason."""
    return [
        Case(_COMP, "constant prior", lambda: _skipped_case(_constant, "constant")),
        Case(_COMP, "near-constant prior (1e-14)", lambda: _skipped_case(_near_constant, "constant")),
        Case(_COMP, "all-zero prior", lambda: _skipped_case(_zero_prior, "constant")),
        Case(_COMP, "all-NaN prior", lambda: _skipped_case(_all_nan, "valid pixels")),
        Case(_COMP, "all-inf prior", lambda: _skipped_case(_all_inf, "valid pixels")),
        Case(_COMP, "all-invalid prior", lambda: _skipped_case(_all_invalid, "valid pixels")),
        Case(_COMP, "9 valid pixels (< 10)", lambda: _skipped_case(_few_valid, "valid pixels")),
    ]


def depth_solve_cases() -> list[Case]:
    """solve_scale_shift (float32 inputs) vs numpy lstsq in float64; degenerate priors skip as documented."""
    return _solvable_cases() + _degenerate_cases()
