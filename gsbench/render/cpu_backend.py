"""The `cpu` rasterizer: numba-compiled fused forward and hand-written backward.

Same contract and numerical rules as the `torch` reference (`rasterize_torch`): it composites the
per-Gaussian channels (M x C, any C) of the visible Gaussians of a `Projected` and returns
(H x W x C) channel sums and (H x W) final transmittance. Projection stays the shared
differentiable `project_gaussians`; this module is a `torch.autograd.Function` over
(means2d of the visible Gaussians, conics, opacities, channels), so gradients reach
`proj.means2d` (densification reads `means2d.grad`), the conics, opacities and channels, and
autograd carries them through the projection.

How it runs (kernels in gsbench/render/cpu_kernels.py):
1. sort the visible Gaussians by depth (stable), bin them into 16x16 tiles with the reference's
   box-overlap test (serial, O(pairs));
2. forward: one task per tile over all cores (numba prange, dynamic chunks of one tile); each
   Gaussian, front to back, is composited into all channels of the tile's pixels in one pass; per
   pixel only the final transmittance and the index of the last contributing Gaussian are kept;
3. backward: per tile, back to front, the transmittance is recovered as T_k = T_{k+1} / (1 - a_k);
   each (tile, Gaussian) pair gets its own gradient row: the sum over the tile's pixels (row-major
   order) in float64, stored in the working dtype. Tiles are processed in waves (consecutive
   tiles whose rows fit in ROW_BUDGET_BYTES, at least one tile); after each wave the rows are
   added to the per-Gaussian gradients serially in row order (tile index, then depth rank).
Determinism rule: every pixel and every (tile, Gaussian) row is computed by exactly one task in a
fixed order, and the reduction is serial in a fixed order, so the same inputs give bit-identical
outputs and gradients for any number of threads.

Threads: numba uses min(torch.get_num_threads(), NUMBA_NUM_THREADS) threads, so
torch.set_num_threads() governs both backends. Threading layer: numba's `workqueue`, unless
NUMBA_THREADING_LAYER says otherwise. numba's `omp` layer loads the system libgomp next to
PyTorch's own copy; the two OpenMP runtimes' spinning workers then slow every later PyTorch op
by 10-30x on a 2-core machine (measured), so it is not used by default. `workqueue` does not
allow two Python threads to render with the `cpu` backend at the same time.
"""
from __future__ import annotations

import math
import os

import numba
import numpy as np
import torch

from gsbench.render import cpu_kernels as K
from gsbench.render import rules
from gsbench.render.projection import Projected

# Must precede the first parallel kernel launch. Set in the environment too: numba re-reads its
# configuration from the environment whenever os.environ changes, which would undo a plain assignment.
os.environ.setdefault("NUMBA_THREADING_LAYER", "workqueue")
numba.config.THREADING_LAYER = os.environ["NUMBA_THREADING_LAYER"]

ROW_BUDGET_BYTES = 2 * 2**20     # gradient rows of one backward wave (working dtype; at least one tile)
SKIP_MARGIN = 1e-3              # see cpu_kernels: exponent bound below which alpha < ALPHA_MIN surely


def _consts(np_dtype) -> np.ndarray:
    c = np.empty(K.NCONST, dtype=np_dtype)
    c[K.K_ONE] = 1.0
    c[K.K_MHALF] = -0.5
    c[K.K_ZERO] = 0.0
    c[K.K_AMAX] = rules.ALPHA_MAX
    c[K.K_AMIN] = rules.ALPHA_MIN
    c[K.K_TMIN] = rules.T_MIN
    return c


def _set_threads() -> None:
    numba.set_num_threads(max(1, min(torch.get_num_threads(), numba.config.NUMBA_NUM_THREADS)))


def _numpy(t: torch.Tensor) -> np.ndarray:
    return np.ascontiguousarray(t.detach().cpu().numpy())


class _Rasterize(torch.autograd.Function):
    """(means2d (M,2), conics (M,3), opacities (M,), channels (M,C)) -> (out (H,W,C), T (H,W))."""

    @staticmethod
    def forward(ctx, means2d, conics, opacities, channels, radii, depths, width, height, tile_size):
        dtype = channels.dtype
        np_dtype = np.float32 if dtype == torch.float32 else np.float64
        m, n_ch = channels.shape
        order = torch.sort(depths.detach(), stable=True).indices
        md = means2d.detach()[order]
        op = opacities.detach()[order]
        gp = torch.zeros(m, K.NPARAM, dtype=dtype)
        gp[:, K.MX:K.MY + 1] = md
        gp[:, K.CA:K.CC + 1] = conics.detach()[order]
        gp[:, K.OP] = op
        op64 = op.to(torch.float64).clamp(min=rules.ALPHA_MIN)
        gp[:, K.THR] = (torch.log(rules.ALPHA_MIN / op64) - SKIP_MARGIN).to(dtype)
        # screen boxes exactly as the reference computes them (same dtype, same operations)
        r = radii.detach()[order].to(dtype)
        x0, x1 = md[:, 0] - r[:, 0], md[:, 0] + r[:, 0]
        y0, y1 = md[:, 1] - r[:, 1], md[:, 1] + r[:, 1]
        tile_off, ranks = K.bin_tiles(_numpy(x0), _numpy(x1), _numpy(y0), _numpy(y1),
                                      width, height, tile_size)
        gp_np = _numpy(gp)
        ch_np = _numpy(channels.detach()[order])
        pxc = np.arange(width, dtype=np_dtype) + np_dtype(0.5)
        pyc = np.arange(height, dtype=np_dtype) + np_dtype(0.5)
        consts = _consts(np_dtype)
        tiles_x = (width + tile_size - 1) // tile_size
        out = np.empty((height, width, n_ch), dtype=np_dtype)
        t_out = np.empty((height, width), dtype=np_dtype)
        t64 = np.empty((height, width), dtype=np.float64)
        last = np.empty((height, width), dtype=np.int32)
        _set_threads()
        with numba.parallel_chunksize(1):
            K.raster_forward(gp_np, ch_np, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts,
                             out, t_out, t64, last)
        ctx.kernel_args = (gp_np, ch_np, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts, t64, last)
        ctx.order = order
        ctx.m, ctx.n_ch = m, n_ch
        return torch.from_numpy(out), torch.from_numpy(t_out)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_out, g_t):
        gp_np, ch_np, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts, t64, last = ctx.kernel_args
        m, n_ch = ctx.m, ctx.n_ch
        dtype = torch.float32 if gp_np.dtype == np.float32 else torch.float64
        g_out_np = _numpy(g_out.to(dtype))
        g_t_np = _numpy(g_t.to(dtype))
        n_cols = K.G_CH + n_ch
        full_np = np.zeros((m, n_cols), dtype=gp_np.dtype)   # gradients in field order
        n_tiles = tile_off.size - 1
        budget = max(1, ROW_BUDGET_BYTES // (gp_np.itemsize * n_cols))
        _set_threads()
        waves = []                # consecutive tiles whose rows fit in the budget (at least one tile)
        t_lo = 0
        while t_lo < n_tiles:
            t_hi = t_lo + 1
            while t_hi < n_tiles and tile_off[t_hi + 1] - tile_off[t_lo] <= budget:
                t_hi += 1
            if tile_off[t_hi] > tile_off[t_lo]:
                waves.append((t_lo, t_hi))
            t_lo = t_hi
        max_rows = max((int(tile_off[b] - tile_off[a]) for a, b in waves), default=0)
        rows = np.empty((max_rows, n_cols), dtype=gp_np.dtype)
        order_np = ctx.order.numpy()
        for t_lo, t_hi in waves:
            with numba.parallel_chunksize(1):
                K.raster_backward(gp_np, ch_np, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts,
                                  t64, last, g_out_np, g_t_np, t_lo, t_hi, rows)
            K.reduce_rows(tile_off, ranks, order_np, t_lo, t_hi, rows, full_np)
        del rows
        full = torch.from_numpy(full_np)
        need = ctx.needs_input_grad
        return (full[:, K.G_MX:K.G_MY + 1] if need[0] else None,
                full[:, K.G_CA:K.G_CC + 1] if need[1] else None,
                full[:, K.G_OP] if need[2] else None,
                full[:, K.G_CH:] if need[3] else None,
                None, None, None, None, None)


def rasterize_cpu(proj: Projected, channels: torch.Tensor, width: int, height: int,
                  tile_size: int = rules.TILE_SIZE) -> tuple[torch.Tensor, torch.Tensor]:
    """Composite per-Gaussian `channels` (M x C, rows aligned with `proj.ids`) on the CPU.

    Returns (H x W x C) composited channels (no background) and (H x W) final transmittance,
    like `rasterize_torch`, with gradients for means2d, conics, opacities and channels.
    """
    if channels.dim() != 2:
        raise ValueError(f"rasterize_cpu: channels must be (M, C), got {tuple(channels.shape)}")
    if channels.device.type != "cpu" or proj.means2d.device.type != "cpu":
        raise ValueError("render backend 'cpu' needs CPU tensors; use backend='gsplat' or 'auto' on CUDA")
    dtype = channels.dtype
    if dtype not in (torch.float32, torch.float64):
        raise ValueError(f"render backend 'cpu' supports float32 and float64, got {dtype}")
    means2d = proj.means2d[proj.ids]
    conics, opacities = proj.conics, proj.opacities
    if not (means2d.dtype == conics.dtype == opacities.dtype == dtype):
        raise ValueError("rasterize_cpu: means2d, conics, opacities and channels must share one dtype")
    m, n_ch = channels.shape
    if n_ch < 1:
        raise ValueError("rasterize_cpu: channels needs at least one column")
    if m == 0:
        out = torch.zeros(height, width, n_ch, dtype=dtype)
        t_final = torch.ones(height, width, dtype=dtype)
        if torch.is_grad_enabled() and (channels.requires_grad or opacities.requires_grad):
            # nothing visible: stay attached to the graph (exact zero gradients), as the reference does
            out = out + channels[:0].sum()
            t_final = t_final + opacities[:0].sum()
        return out, t_final
    if width * height > 2**31 - 1 or not math.isfinite(width * height):
        raise ValueError(f"rasterize_cpu: image {width}x{height} is too large")
    radii = proj.radii[proj.ids]
    return _Rasterize.apply(means2d, conics, opacities, channels, radii, proj.depths, width, height, tile_size)
