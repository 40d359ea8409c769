"""The SSIM training loss on the CPU: a numba forward and a hand-written backward.

`losses.ssim` runs this for CPU tensors; it is the same function as `losses.ssim_map(...).mean()`
(Gaussian window, zero padding, 3DGS's constants: the one SSIM definition, gsbench/metrics/ssim_definition.py,
whose window taps and C1, C2 `losses.ssim` passes in): the blurs in the images' dtype as the PyTorch
version computes them, the per-pixel SSIM, its derivatives and the sum in float64, the result in the
images' dtype. The PyTorch version spends most of its time in two grouped convolutions and their backward
(about 11 ms per 256x192 RGB step on 2 cores); here each of the five local statistics of a channel
(mu_a, mu_b, E[a^2], E[b^2], E[ab]) is one separable blur, and the backward uses that a zero-padded
blur with a symmetric window is its own adjoint: d loss / d image is a blur of the per-pixel
derivatives with respect to the statistics, which the forward computes and keeps.

Each blurred map, SSIM row and gradient row is one task's (numba prange over the run's threads),
and the row sums are added in a fixed order, so results do not depend on the thread count.
"""
from __future__ import annotations

import numpy as np
import torch
from numba import njit, prange

from gsbench.metrics.ssim_definition import SSIM_TRAIN_DEN_FLOOR
from gsbench.render.cpu_backend import set_numba_threads

_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)
CLAMP = SSIM_TRAIN_DEN_FLOOR     # the denominator's floor, as in `losses.ssim_map`


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
def _tap_sum(src, g, x, zero):
    """Output x of `_hblur`: zero + the taps that fall inside src, in tap order."""
    w = src.size
    r = g.size // 2
    acc = zero
    for t in range(g.size):
        j = x + t - r
        if j >= 0 and j < w:
            acc += g[t] * src[j]
    return acc


@njit(inline="always", **_OPTS)
def _hblur(src_row, g, out):
    """out = src_row filtered by the window g with zero padding (unit-stride loops: they vectorise).
    Every output is 0 + its in-range taps added in tap order. For 11 taps (3DGS's window) the inner
    pixels take the sum written out, indexed from 0 with unsigned indices: the same additions in the
    same order, so the same bits, and it vectorises with one store per pixel instead of eleven."""
    w = src_row.size
    k = g.size
    r = k // 2
    if k == 11 and w > 10:
        zero = g[0] - g[0]
        g0, g1, g2, g3, g4, g5, g6, g7, g8, g9, g10 = g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], g[8], g[9], g[10]
        n = w - 10
        o = out[5:w - 5]
        s0, s1, s2, s3 = src_row[0:n], src_row[1:n + 1], src_row[2:n + 2], src_row[3:n + 3]
        s4, s5, s6, s7 = src_row[4:n + 4], src_row[5:n + 5], src_row[6:n + 6], src_row[7:n + 7]
        s8, s9, s10 = src_row[8:n + 8], src_row[9:n + 9], src_row[10:n + 10]
        for i in range(np.uint64(0), np.uint64(n)):
            o[i] = (((((((((((zero + g0 * s0[i]) + g1 * s1[i]) + g2 * s2[i]) + g3 * s3[i]) + g4 * s4[i])
                          + g5 * s5[i]) + g6 * s6[i]) + g7 * s7[i]) + g8 * s8[i]) + g9 * s9[i]) + g10 * s10[i])
        for x in range(5):
            out[x] = _tap_sum(src_row, g, x, zero)
            out[w - 5 + x] = _tap_sum(src_row, g, w - 5 + x, zero)
        return
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
    """dst_row = row y of the column filter over rows held in `ring` (row yy at yy % window): 0 + the
    in-range taps in tap order; for 11 taps and an inner row, written out as in `_hblur`."""
    k = g.size
    r = k // 2
    if k == 11 and y >= 5 and y < h - 5:
        zero = g[0] - g[0]
        g0, g1, g2, g3, g4, g5, g6, g7, g8, g9, g10 = g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], g[8], g[9], g[10]
        r0, r1, r2, r3 = ring[(y - 5) % 11], ring[(y - 4) % 11], ring[(y - 3) % 11], ring[(y - 2) % 11]
        r4, r5, r6, r7 = ring[(y - 1) % 11], ring[y % 11], ring[(y + 1) % 11], ring[(y + 2) % 11]
        r8, r9, r10 = ring[(y + 3) % 11], ring[(y + 4) % 11], ring[(y + 5) % 11]
        for x in range(np.uint64(0), np.uint64(dst_row.size)):
            dst_row[x] = (((((((((((zero + g0 * r0[x]) + g1 * r1[x]) + g2 * r2[x]) + g3 * r3[x]) + g4 * r4[x])
                                + g5 * r5[x]) + g6 * r6[x]) + g7 * r7[x]) + g8 * r8[x]) + g9 * r9[x]) + g10 * r10[x])
        return
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
def _ssim_rows(st, c1, c2, n_c, d, row_sums):
    """SSIM of every pixel from the statistics st (5C, H, W: mu_a, mu_b, E[a^2], E[b^2], E[ab] of each
    channel), its derivatives with respect to them (d (4C, H, W): d_mu1, d_mu2, d_e, d_e12 blocks of C
    maps; that w.r.t. E[a^2] equals that w.r.t. E[b^2]) and the sum of each (channel, row) in
    row_sums. Each row's SSIM values are summed in a second loop: with the sum in the pixel loop
    (a float64 reduction in a fixed order) the loop did not vectorise, about 3x slower."""
    h = st.shape[1]
    w = st.shape[2]
    for cy in prange(n_c * h):
        ch = cy // h
        y = cy - ch * h
        q = 5 * ch
        sv = np.empty(w)
        for x in range(w):
            m1 = np.float64(st[q, y, x])
            m2 = np.float64(st[q + 1, y, x])
            n1 = 2.0 * m1 * m2 + c1                     # numerator and denominator factors
            n2 = 2.0 * (np.float64(st[q + 4, y, x]) - m1 * m2) + c2
            q1 = m1 * m1 + m2 * m2 + c1
            q2 = (np.float64(st[q + 2, y, x]) - m1 * m1) + (np.float64(st[q + 3, y, x]) - m2 * m2) + c2
            den = q1 * q2
            ok = den >= CLAMP                           # else clamped: no gradient through the denominator
            inv = 1.0 / (den if ok else CLAMP)
            s = n1 * n2 * inv
            dq = s * (q2 - q1) if ok else 0.0
            d[ch, y, x] = 2.0 * (m2 * (n2 - n1) - m1 * dq) * inv
            d[n_c + ch, y, x] = 2.0 * (m1 * (n2 - n1) - m2 * dq) * inv
            d[2 * n_c + ch, y, x] = -s * q1 * inv if ok else 0.0
            d[3 * n_c + ch, y, x] = 2.0 * n1 * inv
            sv[x] = s
        total = 0.0
        for x in range(w):
            total += sv[x]
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
        row_sums = np.empty(n_c * h)
        _ssim_rows(st, c1, c2, n_c, d, row_sums)
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
