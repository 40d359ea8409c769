"""The SSIM training loss on the CPU: a numba forward and a hand-written backward.

`losses.ssim` runs this for CPU tensors; it is the same function as `losses.ssim_map(...).mean()`
(Gaussian window, zero padding, 3DGS's constants), computed in float64 and returned in the images'
dtype. The PyTorch version spends most of its time in two grouped convolutions and their backward
(about 11 ms per 256x192 RGB step on 2 cores); here each of the five local statistics of a channel
(mu_a, mu_b, E[a^2], E[b^2], E[ab]) is one separable blur, and the backward uses that a zero-padded
blur with a symmetric window is its own adjoint: d loss / d image is a blur of the per-pixel
derivatives with respect to the statistics, which the forward computes and keeps.

Serial on purpose: each map is a few hundred microseconds, and results do not depend on the thread
count (the pixel sum runs in a fixed order).
"""
from __future__ import annotations

import numpy as np
import torch
from numba import njit, prange

from gsbench.render.cpu_backend import set_numba_threads

_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)
CLAMP = 1e-12            # the denominator's floor, as in `losses.ssim_map`


@njit(inline="always", **_OPTS)
def _source_row(a, b, ch, kind, y, out):
    """Row y of the map a statistic blurs: a, b, a^2, b^2 or ab of channel ch (kind 0..4) of the
    (H, W, C) images a, b, in their dtype (as the PyTorch version forms them)."""
    ar = a[y, :, ch]
    br = b[y, :, ch]
    n = np.uint64(out.size)
    if kind == 0:
        for x in range(n):
            out[x] = ar[x]
    elif kind == 1:
        for x in range(n):
            out[x] = br[x]
    elif kind == 2:
        for x in range(n):
            out[x] = ar[x] * ar[x]
    elif kind == 3:
        for x in range(n):
            out[x] = br[x] * br[x]
    else:
        for x in range(n):
            out[x] = ar[x] * br[x]


@njit(inline="always", **_OPTS)
def _hblur(src_row, g, out):
    """out = src_row filtered by the window g with zero padding (unit-stride loops: they vectorise)."""
    w = src_row.size
    k = g.size
    r = k // 2
    out[:] = 0.0
    for t in range(k):
        off = t - r
        gt = g[t]
        lo = max(0, -off)
        n = min(w, w - off) - lo
        o = out[lo:lo + n]
        i_ = src_row[lo + off:lo + off + n]
        for i in range(np.uint64(0), np.uint64(n)):
            o[i] += gt * i_[i]


@njit(inline="always", **_OPTS)
def _vblur_row(ring, g, y, h, dst_row):
    """dst_row = row y of the column filter over rows held in `ring` (row yy at yy % window)."""
    k = g.size
    r = k // 2
    dst_row[:] = 0.0
    for t in range(max(0, r - y), min(k, h + r - y)):
        gt = g[t]
        src = ring[(y + t - r) % k]
        for x in range(np.uint64(0), np.uint64(dst_row.size)):
            dst_row[x] += gt * src[x]


@njit(parallel=True, **_OPTS)
def _blur_stats(a, b, g, dst):
    """dst[5 ch + kind] = the separable zero-padded blur of map `kind` (`_source_row`) of channel ch
    of the (H, W, C) images a, b. One map per task; each keeps a ring of its last `window`
    row-filtered rows, so no full-size scratch image is needed."""
    h, w, n_c = a.shape
    k = g.size
    r = k // 2
    for q in prange(5 * n_c):
        ch = q // 5
        kind = q - 5 * ch
        ring = np.empty((k, w), dst.dtype)
        row = np.empty(w, dst.dtype)
        done = 0                                   # rows filtered along x so far
        for y in range(h):
            while done < min(h, y + r + 1):
                _source_row(a, b, ch, kind, done, row)
                _hblur(row, g, ring[done % k])
                done += 1
            _vblur_row(ring, g, y, h, dst[q, y])


@njit(parallel=True, **_OPTS)
def _blur_stack(src, g, maps, dst):
    """dst[q] = the separable zero-padded blur of src[maps[q]] (src an (M, H, W) stack), as
    `_blur_stats` does it."""
    h, w = src.shape[1], src.shape[2]
    k = g.size
    r = k // 2
    for q in prange(maps.size):
        m = maps[q]
        ring = np.empty((k, w), dst.dtype)
        done = 0
        for y in range(h):
            while done < min(h, y + r + 1):
                _hblur(src[m, done], g, ring[done % k])
                done += 1
            _vblur_row(ring, g, y, h, dst[q, y])


@njit(parallel=True, **_OPTS)
def _ssim_rows(st, c1, c2, n_c, d_mu1, d_mu2, d_e, d_e12, row_sums):
    """SSIM of every pixel from the statistics st (5C, H, W: mu_a, mu_b, E[a^2], E[b^2], E[ab] of each
    channel), its derivatives with respect to them (d_*, C x H x W; that w.r.t. E[a^2] equals that
    w.r.t. E[b^2]) and the sum of each (channel, row) in row_sums."""
    h = st.shape[1]
    w = np.uint64(st.shape[2])
    for cy in prange(n_c * h):
        ch = cy // h
        y = cy - ch * h
        q = 5 * ch
        m1r, m2r, e11r, e22r, e12r = st[q, y], st[q + 1, y], st[q + 2, y], st[q + 3, y], st[q + 4, y]
        o_mu1, o_mu2, o_e, o_e12 = d_mu1[ch, y], d_mu2[ch, y], d_e[ch, y], d_e12[ch, y]
        total = 0.0
        for x in range(np.uint64(0), w):
            m1 = np.float64(m1r[x])
            m2 = np.float64(m2r[x])
            n1 = 2.0 * m1 * m2 + c1                     # numerator and denominator factors
            n2 = 2.0 * (np.float64(e12r[x]) - m1 * m2) + c2
            q1 = m1 * m1 + m2 * m2 + c1
            q2 = (np.float64(e11r[x]) - m1 * m1) + (np.float64(e22r[x]) - m2 * m2) + c2
            den = q1 * q2
            ok = den >= CLAMP                           # else clamped: no gradient through the denominator
            inv = 1.0 / (den if ok else CLAMP)
            s = n1 * n2 * inv
            dq = s * (q2 - q1) if ok else 0.0
            o_mu1[x] = 2.0 * (m2 * (n2 - n1) - m1 * dq) * inv
            o_mu2[x] = 2.0 * (m1 * (n2 - n1) - m2 * dq) * inv
            o_e[x] = -s * q1 * inv if ok else 0.0
            o_e12[x] = 2.0 * n1 * inv
            total += s
        row_sums[cy] = total


@njit(parallel=True, **_OPTS)
def _grad_rows(x_img, o_img, bl, per, i_mu, scale, out):
    """out (H, W, C, the images' dtype) = scale * (B(d_mu) + 2 x B(d_e) + o B(d_e12)), with x, o the
    (H, W, C) images; bl (per x C, H, W) holds each channel's blurred derivative maps B(d_e),
    B(d_e12), then the B(d_mu) of the images that need a gradient; i_mu picks which."""
    h, w, n_c = x_img.shape
    for y in prange(h):
        for ch in range(n_c):
            be, b12, bm = bl[per * ch, y], bl[per * ch + 1, y], bl[per * ch + i_mu, y]
            for x in range(np.uint64(0), np.uint64(w)):
                out[y, x, ch] = scale * (np.float64(bm[x]) + 2.0 * np.float64(x_img[y, x, ch]) * np.float64(be[x])
                                         + np.float64(o_img[y, x, ch]) * np.float64(b12[x]))


class _SSIMMean(torch.autograd.Function):
    @staticmethod
    def forward(ctx, img1, img2, window, c1, c2):
        # C order: one compiled layout (a strided view would compile a second, 'A', variant)
        a, b = np.ascontiguousarray(img1.detach().numpy()), np.ascontiguousarray(img2.detach().numpy())
        h, w, n_c = a.shape
        set_numba_threads()
        st = np.empty((5 * n_c, h, w), a.dtype)
        _blur_stats(a, b, window, st)
        d = np.empty((4 * n_c, h, w), a.dtype)                  # d_mu1, d_mu2, d_e, d_e12 of every channel
        d_mu1, d_mu2, d_e, d_e12 = d[:n_c], d[n_c:2 * n_c], d[2 * n_c:3 * n_c], d[3 * n_c:]
        row_sums = np.empty(n_c * h)
        _ssim_rows(st, c1, c2, n_c, d_mu1, d_mu2, d_e, d_e12, row_sums)
        ctx.saved = (a, b, window, d)
        return torch.tensor(float(row_sums.sum()) / max(a.size, 1), dtype=img1.dtype)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_out):
        a, b, window, d = ctx.saved
        h, w, n_c = a.shape
        want_a, want_b = ctx.needs_input_grad[:2]
        # per channel, in the order _grad_rows reads: B(d_e), B(d_e12), then B(d_mu1), B(d_mu2) where wanted
        blocks = [2, 3] + [0] * bool(want_a) + [1] * bool(want_b)      # their blocks in d
        per = len(blocks)
        maps = (np.array(blocks)[None, :] * n_c + np.arange(n_c)[:, None]).reshape(-1)
        bl = np.empty((per * n_c, h, w), a.dtype)
        _blur_stack(d, window, maps, bl)
        scale = float(g_out) / max(a.size, 1)
        dtype = g_out.dtype
        grads = []
        for want, x, o, i_mu in ((want_a, a, b, 2), (want_b, b, a, 2 + bool(want_a))):
            if want:
                out = np.empty_like(x)
                _grad_rows(x, o, bl, per, i_mu, scale, out)
                grads.append(torch.from_numpy(out).to(dtype))
            else:
                grads.append(None)
        return grads[0], grads[1], None, None, None


def ssim_mean_cpu(img1: torch.Tensor, img2: torch.Tensor, window: np.ndarray, c1: float, c2: float) -> torch.Tensor:
    """Mean SSIM of two (H, W, C) CPU images (float32 or float64) with the 1D window `window`."""
    dtype = np.float32 if img1.dtype == torch.float32 else np.float64
    return _SSIMMean.apply(img1, img2, np.ascontiguousarray(window, dtype=dtype), float(c1), float(c2))
