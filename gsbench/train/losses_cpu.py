"""GaussianDS's non-SSIM training losses on the CPU: numba forwards and hand-written backwards.

Why: on a 2-core CPU the PyTorch versions in `losses.py` (expected depth, the scale-shift depth loss,
TV, L_sem, L_ds) are chains of many small tensor ops whose forward and autograd backward cost 2-4 ms
per 256x192 GaussianDS step, spent in per-op overhead and in passes over memory. Here each is one
autograd Function whose forward is one to four serial passes over its inputs and whose backward writes
the gradient in one. (L1 and `normalised_depth` stay PyTorch: a few ops each, no faster here.)

`losses.py` dispatches here for CPU tensors of one float dtype; its PyTorch code stays the reference.
The functions are the same, guards included (clamp floors, masks, the scale-shift `ok` logic, 0 when
nothing counts), and the gradients are PyTorch autograd's (detached parts stay detached: the scale
and shift of the depth loss). Inputs are read in their dtype, the
arithmetic runs in float64 (thresholds compared in the inputs' dtype, as PyTorch does), and sums run
serially in a fixed order on 8 interleaved partial sums, so results never depend on the thread count.
Outputs, gradients and the per-pixel values kept for the backward are in the inputs' dtype.
"""
from __future__ import annotations

import numpy as np
import torch
from numba import njit

_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)
_NONE = np.zeros(0, dtype=np.bool_)      # no edge mask: every pixel with a target counts
TV_FLOOR = 1e-30                          # tv_loss's clamp_min of the squared gradient norm
BLOCK = 1024                              # pixels per block of the blocked passes (a multiple of 8)


# ---------------------------------------------------------------------------- kernels
# Element-wise work runs in unit-stride loops over slices indexed from 0 (they vectorise; an offset index
# does not); sums go through `_addto` (8 independent chains of additions: fast, and in a fixed order).
@njit(inline="always", **_OPTS)
def _addto(acc, buf, n):
    """acc[j] += buf[i] for the i < n with i % 8 == j, in increasing i."""
    s0, s1, s2, s3, s4, s5, s6, s7 = acc[0], acc[1], acc[2], acc[3], acc[4], acc[5], acc[6], acc[7]
    n8 = n - n % 8
    for o in range(0, n8, 8):
        s0 += buf[o]
        s1 += buf[o + 1]
        s2 += buf[o + 2]
        s3 += buf[o + 3]
        s4 += buf[o + 4]
        s5 += buf[o + 5]
        s6 += buf[o + 6]
        s7 += buf[o + 7]
    acc[0], acc[1], acc[2], acc[3], acc[4], acc[5], acc[6], acc[7] = s0, s1, s2, s3, s4, s5, s6, s7
    for i in range(n8, n):
        acc[i % 8] += buf[i]


@njit(inline="always", **_OPTS)
def _total(acc):
    """The 8 partial sums added in a fixed order."""
    return ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))


@njit(inline="always", **_OPTS)
def _sign8(d):
    """sign(d) as int8: 0 at 0 and at NaN (PyTorch's abs backward gives 0 there)."""
    return np.int8(d > 0.0) - np.int8(d < 0.0)


@njit(inline="always", **_OPTS)
def _weights(has, edges, p0, p1, wp, wi):
    """wp[j] and wi[j] = has & edges (edges only if size > 0) of pixel p0 + j as 0/1 in float64 and int8;
    returns the number of pixels with has and with has & edges."""
    n_h = 0
    n_b = 0
    hv = has[p0:p1]
    if edges.size:
        ev = edges[p0:p1]
        for j in range(p1 - p0):
            both = hv[j] & ev[j]
            n_h += hv[j]
            n_b += both
            wp[j] = np.float64(both)
            wi[j] = np.int8(both)
    else:
        for j in range(p1 - p0):
            n_h += hv[j]
            wp[j] = np.float64(hv[j])
            wi[j] = np.int8(hv[j])
        n_b = n_h
    return n_h, n_b


@njit(inline="always", **_OPTS)
def _abs1(av, bv, o, wi, sg):
    """|a[o] - b[o]| in float64; sg[o] = wi sign(a[o] - b[o]) (wi 0 or 1) for the backward."""
    d = np.float64(av[o]) - np.float64(bv[o])
    sg[o] = _sign8(d) * wi
    return abs(d)


@njit(**_OPTS)
def _abs_diff_fwd(a, b, c, has, edges, sg):
    """(sum of |a - b| w, pixels with has, pixels with has & edges) of flat a, b of P pixels x c values,
    w of a pixel = has & edges as a 0/1 factor; sg = w sign(a - b) (int8).
    The factor multiplies as in PyTorch: a NaN where w = 0 still shows. c = 1 and 3 (the default
    latent size) are written out: a loop over a variable c does not vectorise (other c: 2-4x slower
    per value)."""
    acc = np.zeros(8)
    n_pix = a.size // c
    buf = np.empty(BLOCK)
    vals = np.empty(BLOCK * c if c != 1 and c != 3 else 0)
    wp = np.empty(BLOCK)
    wi = np.empty(BLOCK, np.int8)
    n_h = 0
    n_b = 0
    for p0 in range(0, n_pix, BLOCK):
        p1 = min(p0 + BLOCK, n_pix)
        h, e = _weights(has, edges, p0, p1, wp, wi)
        n_h += h
        n_b += e
        av, bv, sv = a[p0 * c:p1 * c], b[p0 * c:p1 * c], sg[p0 * c:p1 * c]
        if c == 1:
            for j in range(p1 - p0):
                buf[j] = _abs1(av, bv, j, wi[j], sv) * wp[j]
        elif c == 3:
            for j in range(p1 - p0):
                w = wi[j]
                o = 3 * j
                buf[j] = ((_abs1(av, bv, o, w, sv) + _abs1(av, bv, o + 1, w, sv)) + _abs1(av, bv, o + 2, w, sv)) * wp[j]
        else:                      # every value to the sums (a per-pixel sum would be one long chain)
            for j in range(p1 - p0):
                w, wk = wp[j], wi[j]
                ao, bo, so, vo = av[j * c:j * c + c], bv[j * c:j * c + c], sv[j * c:j * c + c], vals[j * c:j * c + c]
                for k in range(c):
                    vo[k] = _abs1(ao, bo, k, wk, so) * w
            _addto(acc, vals, (p1 - p0) * c)
            continue
        _addto(acc, buf, p1 - p0)
    return _total(acc), n_h, n_b


@njit(**_OPTS)
def _scale_int8(sg, scale, out):
    """out = scale sg: the gradient of `_abs_diff_fwd`'s sum times scale (-scale: with respect to b)."""
    for i in range(sg.size):
        out[i] = scale * np.float64(sg[i])


@njit(**_OPTS)
def _expected_fwd(d, a, eps, out):
    """out = d / a where a > eps (eps in a's dtype: there the clamp_min(eps) is inactive), 0 elsewhere."""
    for i in range(d.size):
        q = np.float64(d[i]) / np.float64(a[i])
        out[i] = q if a[i] > eps else 0.0


@njit(**_OPTS)
def _expected_bwd(d, a, eps, g, gd, ga):
    """The backward of `_expected_fwd`: gd = g / a and ga = -g (d / a) / a on the covered pixels, 0
    elsewhere (ga skipped when size 0)."""
    if ga.size:
        for i in range(d.size):
            ai, gi = np.float64(a[i]), np.float64(g[i])
            q = gi / ai
            r = -gi * (np.float64(d[i]) / ai) / ai
            gd[i] = q if a[i] > eps else 0.0
            ga[i] = r if a[i] > eps else 0.0
    else:
        for i in range(d.size):
            q = np.float64(g[i]) / np.float64(a[i])
            gd[i] = q if a[i] > eps else 0.0


@njit(**_OPTS)
def _tv_fwd(d, h, w, eps, cx, cy):
    """Sum over the cells (y < H-1, x < W-1) of sqrt(max(dx^2 + dy^2 + eps, TV_FLOOR)) of the (H, W)
    map d (flat), and the cell's dx / sqrt(.), dy / sqrt(.) (0 where the floor is active: no gradient)
    at [y + 1, x + 1] of the zero-filled (H + 1, W + 1) cx, cy (flat)."""
    acc = np.zeros(8)
    buf = np.empty(w - 1)
    for y in range(h - 1):
        d0, d1, dn = d[y * w:y * w + w - 1], d[y * w + 1:y * w + w], d[y * w + w:y * w + 2 * w - 1]
        o = (y + 1) * (w + 1) + 1
        ox, oy = cx[o:o + w - 1], cy[o:o + w - 1]
        for x in range(w - 1):
            dx = np.float64(d1[x]) - np.float64(d0[x])
            dy = np.float64(dn[x]) - np.float64(d0[x])
            q = dx * dx + dy * dy + eps
            v = np.sqrt(TV_FLOOR if q < TV_FLOOR else q)      # a NaN stays NaN, as in clamp_min
            buf[x] = v
            inv = 1.0 / v if q >= TV_FLOOR else 0.0
            ox[x] = dx * inv
            oy[x] = dy * inv
        _addto(acc, buf, w - 1)
    return _total(acc)


@njit(**_OPTS)
def _tv_bwd(cx, cy, h, w, scale, out):
    """out (H, W, flat) = scale x the adjoint of the forward differences applied to the cells' cx, cy."""
    for y in range(h):
        o = (y + 1) * (w + 1)
        xl, x0, yu, y0 = cx[o:o + w], cx[o + 1:o + w + 1], cy[o - w:o], cy[o + 1:o + w + 1]
        ov = out[y * w:y * w + w]
        for x in range(w):
            ov[x] = scale * ((np.float64(xl[x]) + np.float64(yu[x])) - (np.float64(x0[x]) + np.float64(y0[x])))


@njit(inline="always", **_OPTS)
def _used(dv, pv, mv, i, disparity, d_eps):
    """(w, x, r) of pixel i of the depth loss: w = 1.0 where used (depth > d_eps, valid, finite prior)
    else 0.0; the prior x and the rendered r (1 / depth or depth) where used, 0 elsewhere."""
    pi = pv[i]
    use = (dv[i] > d_eps) & mv[i] & (pi - pi == 0.0)             # pi - pi == 0: pi is finite
    di = np.float64(dv[i])
    ri = 1.0 / di if disparity else di
    return np.float64(use), (np.float64(pi) if use else 0.0), (ri if use else 0.0)


@njit(**_OPTS)
def _scale_shift_fwd(dv, pv, mv, disparity, d_eps, min_n, rel_eps):
    """The scale-shift depth loss of flat maps (`losses.depth_loss` with `_scale_shift_masked`):
    (sum |r - (s x + t)| w, n, ok, s, t), s, t the closed-form fit of r by s x + t on the used pixels,
    magnitude-normalised (no gradient). The per-pixel arithmetic is PyTorch's, masks as 0/1 factors,
    except that x / ax and r / ay multiply by the reciprocal (the passes recompute them instead of
    storing them: they run at memory speed)."""
    size = dv.size
    b1, b2 = np.empty(BLOCK), np.empty(BLOCK)
    i1, i2 = b1.view(np.int64), b2.view(np.int64)
    n = 0
    top_x = top_r = np.int64(0)
    for o in range(0, size, BLOCK):             # n and the largest |x|, |r|: for non-negative floats the
        m = min(BLOCK, size - o)                # bit patterns order as the values (an integer max vectorises)
        d, p, v = dv[o:o + m], pv[o:o + m], mv[o:o + m]
        for i in range(m):
            w, x, r = _used(d, p, v, i, disparity, d_eps)
            n += w > 0.0
            b1[i] = abs(x)
            b2[i] = abs(r)
        for i in range(m):
            top_x = max(top_x, i1[i])
            top_r = max(top_r, i2[i])
    tops = np.array([top_x, top_r]).view(np.float64)
    ax, ay = tops[0], tops[1]
    ok = ax > 0.0
    ax = ax if ok else 1.0
    ay = ay if ay > 0.0 else 1.0
    kx, ky = 1.0 / ax, 1.0 / ay
    nn = max(np.float64(n), 1.0)
    a1, a2 = np.zeros(8), np.zeros(8)
    for o in range(0, size, BLOCK):             # means of the normalised x and r
        m = min(BLOCK, size - o)
        d, p, v = dv[o:o + m], pv[o:o + m], mv[o:o + m]
        for i in range(m):
            w, x, r = _used(d, p, v, i, disparity, d_eps)
            b1[i] = x * kx
            b2[i] = r * ky
        _addto(a1, b1, m)
        _addto(a2, b2, m)
    xm, ym = _total(a1) / nn, _total(a2) / nn
    a1[:] = 0.0
    a2[:] = 0.0
    for o in range(0, size, BLOCK):             # variance and covariance
        m = min(BLOCK, size - o)
        d, p, v = dv[o:o + m], pv[o:o + m], mv[o:o + m]
        for i in range(m):
            w, x, r = _used(d, p, v, i, disparity, d_eps)
            xc = (x * kx - xm) * w
            b1[i] = xc * xc
            b2[i] = xc * ((r * ky - ym) * w)
        _addto(a1, b1, m)
        _addto(a2, b2, m)
    var = _total(a1)
    ok = ok and np.isfinite(var) and var > rel_eps * rel_eps * nn * max(xm * xm, 1.0)
    s_n = _total(a2) / (var if ok else 1.0)
    t_n = ym - s_n * xm
    s, t = s_n * ay / ax, t_n * ay
    ok = ok and np.isfinite(s) and np.isfinite(t)
    s, t = (s, t) if ok else (1.0, 0.0)
    ok = ok and n >= min_n
    if not ok:
        return 0.0, np.float64(n), ok, s, t
    a1[:] = 0.0
    for o in range(0, size, BLOCK):             # sum |residual|
        m = min(BLOCK, size - o)
        d, p, v = dv[o:o + m], pv[o:o + m], mv[o:o + m]
        for i in range(m):
            w, x, r = _used(d, p, v, i, disparity, d_eps)
            b1[i] = abs(r - (s * x + t)) * w
        _addto(a1, b1, m)
    return _total(a1), np.float64(n), ok, s, t


@njit(**_OPTS)
def _scale_shift_bwd(dv, pv, mv, disparity, d_eps, s, t, scale, out):
    """out = scale w sign(r - (s x + t)) dr/ddepth (-r^2 for r = 1 / depth): the gradient of the
    residual sum times scale (where depth is not used, 0)."""
    for i in range(dv.size):
        w, x, r = _used(dv, pv, mv, i, disparity, d_eps)
        res = r - (s * x + t)
        sg = 1.0 if res > 0.0 else (-1.0 if res < 0.0 else 0.0)
        out[i] = scale * (sg * w) * (-(r * r) if disparity else 1.0)


# ---------------------------------------------------------------------------- autograd Functions
def _np(t: torch.Tensor) -> np.ndarray:
    """The tensor's values as a C-contiguous flat array (a view where the tensor is contiguous)."""
    return np.ascontiguousarray(t.detach().numpy()).reshape(-1)


def _scalar(v: float, dtype: torch.dtype) -> torch.Tensor:
    """A 0-dim tensor (the cheapest way to make one)."""
    return torch.scalar_tensor(v, dtype=dtype)


class _AbsDiffMean(torch.autograd.Function):
    @staticmethod
    def forward(ctx, a, b, c, has, edges, over_edges):
        an = _np(a)
        sg = np.empty(an.size, np.int8)
        total, n_has, n_both = _abs_diff_fwd(an, _np(b), c, has, edges, sg)
        nc = max(float((n_both if over_edges else n_has) * c), 1.0)
        ctx.saved = (sg, nc, an.dtype, a.shape)
        return _scalar(total / nc, a.dtype)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_out):
        sg, nc, dtype, shape = ctx.saved
        want_a, want_b = ctx.needs_input_grad[:2]
        g = np.empty(sg.size, dtype)
        _scale_int8(sg, float(g_out) / nc if want_a else -float(g_out) / nc, g)
        g = torch.from_numpy(g.reshape(shape))
        if want_a:
            return g, (-g if want_b else None), None, None, None, None
        return None, g, None, None, None, None


class _Expected(torch.autograd.Function):
    @staticmethod
    def forward(ctx, depth, alpha, eps):
        d, a = _np(depth), _np(alpha)
        eps = a.dtype.type(eps)
        out = np.empty_like(d)
        _expected_fwd(d, a, eps, out)
        ctx.saved = (d, a, eps)
        return torch.from_numpy(out.reshape(depth.shape))

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g):
        d, a, eps = ctx.saved
        gd = np.empty_like(d)
        ga = np.empty_like(a) if ctx.needs_input_grad[1] else a[:0]
        _expected_bwd(d, a, eps, _np(g), gd, ga)
        return (torch.from_numpy(gd.reshape(g.shape)) if ctx.needs_input_grad[0] else None,
                torch.from_numpy(ga.reshape(g.shape)) if ga.size else None, None)


class _TV(torch.autograd.Function):
    @staticmethod
    def forward(ctx, depth, eps):
        h, w = depth.shape
        d = _np(depth)
        cx, cy = np.zeros((h + 1) * (w + 1), d.dtype), np.zeros((h + 1) * (w + 1), d.dtype)
        total = _tv_fwd(d, h, w, eps, cx, cy)
        ctx.saved = (cx, cy, h, w)
        return _scalar(total / ((h - 1) * (w - 1)), depth.dtype)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_out):
        cx, cy, h, w = ctx.saved
        out = np.empty(h * w, cx.dtype)
        _tv_bwd(cx, cy, h, w, float(g_out) / ((h - 1) * (w - 1)), out)
        return torch.from_numpy(out.reshape(h, w)), None


class _ScaleShiftLoss(torch.autograd.Function):
    @staticmethod
    def forward(ctx, depth, p, pv, disparity, d_eps, min_n, rel_eps):
        d, pn, mn = _np(depth), _np(p), _np(pv)
        d_eps = d.dtype.type(d_eps)
        total, n, ok, s, t = _scale_shift_fwd(d, pn, mn, disparity, d_eps, min_n, rel_eps)
        nc = max(n, 1.0)
        ctx.saved = (d, pn, mn, disparity, d_eps, s, t, ok, nc, depth.shape)
        outs = (_scalar(total / nc if ok else 0.0, depth.dtype), torch.tensor(bool(ok)),
                _scalar(s, torch.float64), _scalar(t, torch.float64), _scalar(n, depth.dtype))
        ctx.mark_non_differentiable(*outs[1:])
        return outs

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_loss, *_):
        d, pn, mn, disparity, d_eps, s, t, ok, nc, shape = ctx.saved
        if ok:
            out = np.empty_like(d)
            _scale_shift_bwd(d, pn, mn, disparity, d_eps, s, t, float(g_loss) / nc, out)
        else:                      # the loss is the constant 0
            out = np.zeros_like(d)
        return torch.from_numpy(out.reshape(shape)), None, None, None, None, None, None


# ---------------------------------------------------------------------------- entry points (losses.py)
def masked_abs_mean_cpu(s_hat: torch.Tensor, target: torch.Tensor, has_target: torch.Tensor,
                        edges: torch.Tensor | None = None, over_edges: bool = False) -> torch.Tensor:
    """`losses.sem_loss` (edges None) and `losses.ds_loss` (edges given; over_edges: average 'edges')
    for (..., d) maps and bool (...) masks on the CPU."""
    e = _NONE if edges is None else _np(edges)
    return _AbsDiffMean.apply(s_hat, target, s_hat.shape[-1], _np(has_target), e, over_edges)


def expected_depth_cpu(depth: torch.Tensor, alpha: torch.Tensor, alpha_eps: float) -> torch.Tensor:
    """depth / alpha where alpha > alpha_eps, else 0 (`losses.expected_depth`)."""
    return _Expected.apply(depth, alpha, alpha_eps)


def tv_cpu(depth: torch.Tensor, eps: float) -> torch.Tensor:
    """Mean isotropic TV of an (H, W) map with H, W >= 2 (`losses.tv_loss`)."""
    return _TV.apply(depth, float(eps))


def scale_shift_loss_cpu(depth: torch.Tensor, p: torch.Tensor, pv: torch.Tensor, disparity: bool,
                         depth_eps: float, min_valid: int, rel_eps: float) -> tuple[torch.Tensor, ...]:
    """(loss, ok, s, t, n_valid) of `losses.depth_loss('scale_shift', ...)`: p the prior in depth's dtype,
    pv its bool validity, both of depth's shape; only the loss carries a gradient."""
    return _ScaleShiftLoss.apply(depth, p, pv, bool(disparity), float(depth_eps), max(2, int(min_valid)),
                                 float(rel_eps))
