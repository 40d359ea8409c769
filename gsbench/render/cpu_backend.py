"""The `cpu` backend: numba-compiled fused projection + rasterization with a hand-written backward.

`render_fused_cpu(field, camera)` (what `render(..., backend="cpu")` calls) is one
`torch.autograd.Function` (`_FusedRender`) from the raw field tensors (means, log_scales, quats,
opacity_logits), the rgb of the visible Gaussians (plain colours indexed, or SH evaluated in
torch: cheap, and autograd carries it to the colours and means) and the features to
(H x W x (4 + d)) channel sums (rgb, depth = camera z, features) and (H x W) final transmittance:
1. projection (`_Projection`; kernels in gsbench/render/cpu_projection.py): camera points and
   projected centres with the reference's operations in its order, in the working dtype (numpy:
   depth order, depth channel and means2d equal `project_gaussians`' bit for bit), then
   covariance, conic, opacity, culling and radii in one numba pass per Gaussian (float64,
   rounded to the working dtype);
2. rasterization as below; its backward gives per-visible-Gaussian gradients of means2d, conic,
   opacity and channels; the depth channel's gradient is that of camera z;
3. projection backward (numba, one Gaussian per iteration, float64): those gradients to means,
   log_scales, quats and opacity logits (no reduction, so deterministic).
`means2d` (N, 2) is a leaf tensor holding the projected centres and passed to the Function as an
extra input whose value is not read: the Function returns d loss / d means2d (pixel units) for it,
so `out.means2d.grad` is filled after backward exactly as the reference's retained gradient
(densification reads it). Like the reference's, it requires grad only when `field.means` does.

`rasterize_cpu(proj, channels, W, H)` keeps the rasterizer-only API (`_Rasterize`: the same
kernels behind a Function over means2d, conics, opacities and channels of a torch `Projected`).

How it runs (kernels in gsbench/render/cpu_binning.py and cpu_kernels.py, which says how they
vectorise):
1. sort the visible Gaussians by depth (stable), pack the kernels' inputs in that order in one
   numba pass (`_pack`), bin them into 16x16 tiles with the reference's box-overlap test (both threads,
   O(pairs));
2. forward: one worker per thread (numba prange), each taking the next tile, costliest first, from
   a shared counter until none is left (gsbench/render/cpu_sched.py: numba's `workqueue` layer
   splits a prange statically); each Gaussian of a tile, front to back, is composited into all
   channels of its pixels; per pixel only the final transmittance and the index of the last
   contributing Gaussian are kept;
3. backward: per tile, back to front, the transmittance is recovered as T_k = T_{k+1} / (1 - a_k);
   each (tile, Gaussian) pair gets its own gradient row: the sum over the tile's pixels in
   float64, stored in the working dtype. Tiles are processed in waves (consecutive
   tiles whose rows fit in ROW_BUDGET_BYTES, at least one tile; within a wave, scheduled as the
   forward's); after each wave the rows are
   added to the per-Gaussian gradients serially in row order (tile index, then depth rank); one
   numba pass (`_scatter_grads`) hands them to the outputs and to the projection's backward.
Determinism rule: every pixel and every (tile, Gaussian) row is computed by exactly one task in a
fixed order, and the reduction is serial in a fixed order, so the same inputs give bit-identical
outputs and gradients for any number of threads.

Threads: numba uses min(torch.get_num_threads(), NUMBA_NUM_THREADS) threads, so
torch.set_num_threads() governs both backends; inside a training step torch runs on one thread and
numba on the count torch had. Threading layer: `tbb` where the tbb package is installed, else
`workqueue` (gsbench/render/threads.py says why; results are the same bits on both). `workqueue`
does not allow two Python threads to render with the `cpu` backend at the same time.
"""
from __future__ import annotations

import math

import numba
import numpy as np
import torch

from gsbench.camera import Camera
from gsbench.gaussians import GaussianField, sh_rgb
from gsbench.render import cpu_binning, cpu_bounds, cpu_sched, rules
from gsbench.render import cpu_kernels as K
from gsbench.render import cpu_projection as P
from gsbench.render.projection import Projected, camera_tensors
from gsbench.render.threads import kernel_threads, select_numba_threading_layer, tbb_unusable
from gsbench.step_timers import timed

# Must precede the first parallel kernel launch (gsbench.render chose it, in the environment; numba
# re-reads its configuration from the environment whenever os.environ changes).
_layer = select_numba_threading_layer()
if _layer == "tbb":
    try:
        from numba.np.ufunc import tbbpool  # noqa: F401  (numba's tbb layer: fails on a library it cannot use)
    except ImportError as e:
        _layer = tbb_unusable(e)
numba.config.THREADING_LAYER = _layer

_TORCH = {np.float32: torch.float32, np.float64: torch.float64}
ROW_BUDGET_BYTES = 16 * 2**20    # gradient rows of one backward wave (working dtype; at least one tile)
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


def set_numba_threads() -> int:
    """numba's thread count for the next parallel kernel: `threads.kernel_threads()` (torch's, or the
    budget of a training step whose torch ops run on one thread), within NUMBA_NUM_THREADS (returned)."""
    n = max(1, min(kernel_threads(), numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(n)
    return n


def _numpy(t: torch.Tensor) -> np.ndarray:
    return np.ascontiguousarray(t.detach().cpu().numpy())


def _numpy64(t: torch.Tensor) -> np.ndarray:
    return np.ascontiguousarray(t.detach().cpu().numpy(), dtype=np.float64)


@numba.njit(parallel=True, cache=True, fastmath=False, error_model="numpy", nogil=True)
def _pack(order, md, conics, op, radii, ch, amin, margin, gp, ch_s, boxes, reach):
    """The kernels' inputs in depth order, in one pass over the Gaussians (each row on its own, so on
    every thread): gp (M, NPARAM: centre, conic, opacity, THR = log(ALPHA_MIN / max(opacity,
    ALPHA_MIN)) - margin in float64, rounded), the channels ch_s, the screen boxes (x0, x1, y0, y1)
    = centre -+ radius exactly as the reference computes them (the working dtype, the same
    operations), and reach (M, NBOX), the box outside which a row's exponent cannot reach THR
    (`cpu_bounds.box` of the packed row)."""
    for k in numba.prange(order.size):
        g = order[k]
        mx = md[g, 0]
        my = md[g, 1]
        gp[k, K.MX] = mx
        gp[k, K.MY] = my
        gp[k, K.CA] = conics[g, 0]
        gp[k, K.CB] = conics[g, 1]
        gp[k, K.CC] = conics[g, 2]
        gp[k, K.OP] = op[g]
        gp[k, K.THR] = np.log(amin / np.maximum(np.float64(op[g]), amin)) - margin   # NaN stays NaN
        for j in range(K.THR + 1, K.NPARAM):
            gp[k, j] = 0.0
        boxes[1, k] = radii[g, 0]           # the radii rounded to the working dtype (a store casts)
        boxes[3, k] = radii[g, 1]
        rx = boxes[1, k]
        ry = boxes[3, k]
        boxes[0, k] = mx - rx
        boxes[1, k] = mx + rx
        boxes[2, k] = my - ry
        boxes[3, k] = my + ry
        for c in range(ch.shape[1]):
            ch_s[k, c] = ch[g, c]
        cx, cy, hx, hy = cpu_bounds.box(gp[k, K.MX], gp[k, K.MY], gp[k, K.CA], gp[k, K.CB], gp[k, K.CC],
                                        gp[k, K.THR])
        reach[k, cpu_bounds.E_CX] = cx
        reach[k, cpu_bounds.E_CY] = cy
        reach[k, cpu_bounds.E_HX] = hx
        reach[k, cpu_bounds.E_HY] = hy


@numba.njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _scatter_grads(full, ids, g_rgb, g_feat, g_m2d, gr):
    """The raster's gradient rows (M, G_CH + 4 + d; row i = Gaussian ids[i]) to the fused render's
    outputs in one pass: g_rgb (M, 3) of the visible rows, g_feat (N, d) and g_m2d (N, 2) at rows ids
    (the others stay zero), and gr (M, NPROJ) float64, the projected rows' gradients that
    `project_backward` takes (means2d, conic, opacity, depth = camera z)."""
    for i in range(ids.size):
        g = ids[i]
        for k in range(3):
            g_rgb[i, k] = full[i, K.G_CH + k]
        for k in range(g_feat.shape[1]):
            g_feat[g, k] = full[i, K.G_CH + 4 + k]
        g_m2d[g, 0] = full[i, K.G_MX]
        g_m2d[g, 1] = full[i, K.G_MY]
        gr[i, P.P_U] = full[i, K.G_MX]
        gr[i, P.P_V] = full[i, K.G_MY]
        gr[i, P.P_CA] = full[i, K.G_CA]
        gr[i, P.P_CB] = full[i, K.G_CB]
        gr[i, P.P_CC] = full[i, K.G_CC]
        gr[i, P.P_OP] = full[i, K.G_OP]
        gr[i, P.P_Z] = full[i, K.G_CH + 3]


def _raster_forward(md, conics, op, ch, radii, z, width, height, tile_size, split=()):
    """Sort, bin and composite (numpy arrays in the working dtype; rows = visible Gaussians).

    Returns (outs, t_final (H,W), state for `_raster_backward`): outs are the channel sums as three
    arrays (H,W,C_0), (H,W,C_1), (H,W,C - C_0 - C_1) with (C_0, C_1) = `split`, (C, 0) by default,
    written by the kernel directly (the fused render's rgb, depth and features need no copies).
    """
    if not 1 <= tile_size <= K.ROW:
        raise ValueError(f"render backend 'cpu': tile_size must be 1..{K.ROW}, got {tile_size}")
    np_dtype = ch.dtype.type
    m, n_ch = ch.shape
    order = cpu_binning.depth_order(z)
    gp = np.empty((m, K.NPARAM), dtype=np_dtype)
    ch_s = np.empty_like(ch)
    boxes = np.empty((4, m), dtype=np_dtype)
    reach = np.empty((m, cpu_bounds.NBOX), dtype=np.float64)    # where each Gaussian can reach THR
    n_workers = set_numba_threads()
    _pack(order, md, conics, op, radii, ch, rules.ALPHA_MIN, SKIP_MARGIN, gp, ch_s, boxes, reach)
    tile_off, ranks = cpu_binning.bin_tiles(boxes[0], boxes[1], boxes[2], boxes[3], width, height, tile_size,
                                            n_workers)
    pxc = np.arange(width + K.ROW, dtype=np_dtype) + np_dtype(0.5)   # lanes past the image's edge read it (masked)
    pyc = np.arange(height, dtype=np_dtype) + np_dtype(0.5)
    consts = _consts(np_dtype)
    tiles_x = (width + tile_size - 1) // tile_size
    sizes = (*split, n_ch - sum(split)) if split else (n_ch, 0, 0)
    outs = tuple(np.empty((height, width, c), dtype=np_dtype) for c in sizes)
    t_out = np.empty((height, width), dtype=np_dtype)
    t64 = np.empty((height, width), dtype=np.float64)
    last = np.empty((height, width), dtype=np.int32)
    spans = np.empty(4 * int(tile_off[-1]), dtype=np.int8)
    K.raster_forward(gp, reach, ch_s, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts,
                     outs, t_out, t64, last, spans, cpu_sched.tile_queue(tile_off), np.zeros(1, np.int64),
                     n_workers)
    state = (gp, ch_s, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts, t64, last, order, spans)
    return outs, t_out, state


def _raster_backward(state, g_outs, g_t_np) -> np.ndarray:
    """Gradient rows (M, G_CH + C) in the caller's row order (working dtype) from d loss / d outs
    (three arrays, laid out as `_raster_forward`'s outs) and d loss / d T."""
    gp, ch_s, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts, t64, last, order, spans = state
    m, n_ch = ch_s.shape
    n_cols = K.G_CH + n_ch
    full = np.zeros((m, n_cols), dtype=gp.dtype)
    n_tiles = tile_off.size - 1
    budget = max(1, ROW_BUDGET_BYTES // (gp.itemsize * n_cols))
    n_workers = set_numba_threads()
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
    rows = np.empty((max_rows, n_cols), dtype=gp.dtype)
    for t_lo, t_hi in waves:
        K.raster_backward(gp, ch_s, tile_off, ranks, pxc, pyc, tiles_x, tile_size, consts, t64, last,
                          g_outs, g_t_np, t_lo, t_hi, rows, spans, cpu_sched.tile_queue(tile_off, t_lo, t_hi),
                          np.zeros(1, np.int64), n_workers)
        K.reduce_rows(tile_off, ranks, order, t_lo, t_hi, rows, full)
    return full


class _Rasterize(torch.autograd.Function):
    """(means2d (M,2), conics (M,3), opacities (M,), channels (M,C)) -> (out (H,W,C), T (H,W))."""

    @staticmethod
    def forward(ctx, means2d, conics, opacities, channels, radii, depths, width, height, tile_size):
        outs, t_out, state = _raster_forward(_numpy(means2d), _numpy(conics), _numpy(opacities),
                                             _numpy(channels), _numpy(radii), _numpy(depths),
                                             width, height, tile_size)
        ctx.state = state
        return torch.from_numpy(outs[0]), torch.from_numpy(t_out)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_out, g_t):
        dtype = torch.from_numpy(ctx.state[0][:0]).dtype
        g_np = _numpy(g_out.to(dtype))
        none = np.zeros(g_np.shape[:2] + (0,), g_np.dtype)
        full = torch.from_numpy(_raster_backward(ctx.state, (g_np, none, none), _numpy(g_t.to(dtype))))
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


# ---------------------------------------------------------------------------- fused render
@numba.njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _camera_points(m, R, t, K, one, pc, uv):
    """pc = R m + t as ((m0 R0 + m1 R1) + m2 R2) + t and uv = (fx x) / z + cx (z = 0 read as 1), each
    operation in the working dtype of m, R, t, K and in the reference's order (no FMA: fastmath is
    off), stored as float64; `one` is 1 in the working dtype. Non-finite or behind-camera points are
    culled by `project_forward`."""
    for g in range(m.shape[0]):
        c0 = ((m[g, 0] * R[0, 0] + m[g, 1] * R[0, 1]) + m[g, 2] * R[0, 2]) + t[0]
        c1 = ((m[g, 0] * R[1, 0] + m[g, 1] * R[1, 1]) + m[g, 2] * R[1, 2]) + t[1]
        c2 = ((m[g, 0] * R[2, 0] + m[g, 1] * R[2, 1]) + m[g, 2] * R[2, 2]) + t[2]
        z = c2 if c2 != 0 else one
        pc[g, 0] = c0
        pc[g, 1] = c1
        pc[g, 2] = c2
        uv[g, 0] = K[0, 0] * c0 / z + K[0, 2]
        uv[g, 1] = K[1, 1] * c1 / z + K[1, 2]


@numba.njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _visible(ok, params, radii, params_vis, radii_vis, means2d):
    """The projected rows of the visible Gaussians (ok), in index order, in one pass: params_vis
    (M, NPROJ) rounded to its working dtype, radii_vis (M, 2), and means2d (N, 2), the rounded
    centres with zeros where culled (numpy's gathers, cast and scatter took about 0.6 ms at 19k)."""
    k = 0
    for g in range(ok.size):
        if ok[g]:
            for j in range(params.shape[1]):
                params_vis[k, j] = params[g, j]
            radii_vis[k, 0] = radii[g, 0]
            radii_vis[k, 1] = radii[g, 1]
            means2d[g, 0] = params_vis[k, P.P_U]
            means2d[g, 1] = params_vis[k, P.P_V]
            k += 1
        else:
            means2d[g, 0] = 0.0
            means2d[g, 1] = 0.0


@numba.njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _channels(rgb, z, feat, ids, ch):
    """ch (M, 4 + d) = the visible Gaussians' rgb (M, 3), depth z (M,) and features feat[ids] (feat
    (N, d)), in one pass."""
    for i in range(ids.size):
        for k in range(3):
            ch[i, k] = rgb[i, k]
        ch[i, 3] = z[i]
        for k in range(feat.shape[1]):
            ch[i, 4 + k] = feat[ids[i], k]


class _Projection:
    """Result of the numba projection of a whole field (float64), shared by forward and backward."""

    def __init__(self, field: GaussianField, camera: Camera):
        dtype = field.means.dtype
        self.np_dtype = np.float32 if dtype == torch.float32 else np.float64
        self.log_scales = _numpy64(field.log_scales)
        self.quats = _numpy64(field.quats)
        self.logits = _numpy64(field.opacity_logits)
        self.n = field.num
        # Camera points and centres in the working dtype with the reference's operations, in its
        # order (R m + t as ((m0 R0 + m1 R1) + m2 R2) + t, then (fx x) / z + cx), in a serial numba pass
        # rather than PyTorch, so no OpenMP workers are left spinning against the numba kernels.
        R_wc, t_wc, Kt = (a.numpy() for a in camera_tensors(camera, "cpu", dtype))
        self.pc = np.empty((self.n, 3), np.float64)
        uv = np.empty((self.n, 2), np.float64)
        _camera_points(_numpy(field.means), R_wc, t_wc, Kt, self.np_dtype(1.0), self.pc, uv)
        w2c = np.asarray(camera.world_to_camera, dtype=np.float64)
        self.cam = P.camera_array(w2c[:3, :3], w2c[:3, 3], np.asarray(camera.K, np.float64),
                                  camera.width, camera.height)
        self.width, self.height = int(camera.width), int(camera.height)
        n = self.n
        ok = np.empty(n, np.bool_)
        params = np.empty((n, P.NPROJ), np.float64)
        self.radii = np.empty((n, 2), np.int64)
        set_numba_threads()
        P.project_forward(self.pc, uv, self.log_scales, self.quats, self.logits, self.cam,
                          self.width, self.height, self.np_dtype == np.float32, ok, params, self.radii)
        self.ids = np.flatnonzero(ok)
        m = self.ids.size
        self.params = np.empty((m, P.NPROJ), self.np_dtype)      # (M, NPROJ) working dtype
        self.radii_vis = np.empty((m, 2), np.int64)
        self.means2d = np.empty((n, 2), self.np_dtype)           # projected centres; zero where culled
        _visible(ok, params, self.radii, self.params, self.radii_vis, self.means2d)


class _FusedRender(torch.autograd.Function):
    """(means, log_scales, quats, opacity_logits, rgb of the visible Gaussians (M,3), features (N,d)
    or None, means2d probe (N,2)) -> (rgb (H,W,3), depth (H,W), features (H,W,d), T (H,W)).
    Separate outputs, so no PyTorch slicing (and slice-backward) ops surround the kernels.

    The projection was run by the caller (`_Projection`, passed as `proj`) because the visible set
    is needed to evaluate SH colours in torch; its values are reused here. `means2d` is a leaf
    holding the projected centres: its value is not read, its gradient is d loss / d means2d
    (pixel units), which lands in `means2d.grad` for densification.
    """

    @staticmethod
    def forward(ctx, means, log_scales, quats, opacity_logits, rgb_vis, features, means2d, proj, tile_size):
        np_dtype = proj.np_dtype
        ids = proj.ids
        m = ids.size
        n_feat = 0 if features is None else features.shape[1]
        n_ch = 4 + n_feat
        ctx.proj, ctx.n_feat, ctx.has_feat = proj, n_feat, features is not None
        h, w = proj.height, proj.width
        if m == 0:
            ctx.state = None
            dt = _TORCH[np_dtype]
            return (torch.zeros(h, w, 3, dtype=dt), torch.zeros(h, w, dtype=dt), torch.zeros(h, w, n_feat, dtype=dt),
                    torch.ones(h, w, dtype=dt))
        prm = proj.params
        ch = np.empty((m, n_ch), dtype=np_dtype)
        _channels(_numpy(rgb_vis), prm[:, P.P_Z], _numpy(features) if n_feat else np.empty((0, 0), np_dtype), ids, ch)
        with timed("raster_forward"):     # the projected columns as views: _pack reads them in one pass
            (rgb, depth, feat), t_out, ctx.state = _raster_forward(
                prm[:, P.P_U:P.P_V + 1], prm[:, P.P_CA:P.P_CC + 1], prm[:, P.P_OP], ch, proj.radii_vis,
                prm[:, P.P_Z], w, h, tile_size, split=(3, 1))
        return (torch.from_numpy(rgb), torch.from_numpy(depth.reshape(h, w)), torch.from_numpy(feat),
                torch.from_numpy(t_out))

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_rgb_img, g_depth_img, g_feat_img, g_t):
        proj = ctx.proj
        need = ctx.needs_input_grad
        dtype = _TORCH[proj.np_dtype]
        n = proj.n
        ids = proj.ids
        m = ids.size
        g_means = np.zeros((n, 3), proj.np_dtype)   # project_backward computes in float64, stores rounded
        g_ls = np.zeros((n, 3), proj.np_dtype)
        g_q = np.zeros((n, 4), proj.np_dtype)
        g_lg = np.zeros(n, proj.np_dtype)
        g_rgb = np.zeros((m, 3), proj.np_dtype)
        g_feat = np.zeros((n, ctx.n_feat), proj.np_dtype)
        g_m2d = np.zeros((n, 2), proj.np_dtype)
        if m > 0:
            h, w, nf = proj.height, proj.width, ctx.n_feat

            def grad_np(g, c):    # d loss / d an output as (H, W, c); zeros where none flowed
                return np.zeros((h, w, c), proj.np_dtype) if g is None else _numpy(g.to(dtype)).reshape(h, w, c)
            g_outs = (grad_np(g_rgb_img, 3), grad_np(g_depth_img, 1), grad_np(g_feat_img, nf))
            with timed("raster_backward"):
                full = _raster_backward(ctx.state, g_outs, grad_np(g_t, 1).reshape(h, w))
            gr = np.empty((m, P.NPROJ), np.float64)
            _scatter_grads(full, ids, g_rgb, g_feat, g_m2d, gr)
            if any(need[:4]):
                set_numba_threads()
                with timed("projection_backward"):
                    P.project_backward(ids, proj.pc, proj.log_scales, proj.quats, proj.logits, proj.cam, gr,
                                       g_means, g_ls, g_q, g_lg)

        def t(a, i):
            return torch.from_numpy(a) if need[i] else None

        return (t(g_means, 0), t(g_ls, 1), t(g_q, 2), t(g_lg, 3), t(g_rgb, 4),
                t(g_feat, 5) if ctx.has_feat else None, t(g_m2d, 6), None, None)


def render_fused_cpu(field: GaussianField, camera: Camera, tile_size: int = rules.TILE_SIZE) -> tuple:
    """The `cpu` backend's render: numba projection + rasterization in one autograd Function.

    Returns (rgb (H,W,3), depth (H,W), features (H,W,d) or None, final transmittance (H,W),
    means2d (N,2), a leaf whose .grad is filled by backward when field.means requires grad,
    radii (N,2) int64, number of visible Gaussians). SH colours are evaluated in torch for the visible Gaussians.
    """
    tensors = [field.means, field.log_scales, field.quats, field.opacity_logits, field.colors]
    if field.features is not None:
        tensors.append(field.features)
    if any(t.device.type != "cpu" for t in tensors):
        raise ValueError("render backend 'cpu' needs CPU tensors; use backend='gsplat' or 'auto' on CUDA")
    dtype = field.means.dtype
    if dtype not in (torch.float32, torch.float64):
        raise ValueError(f"render backend 'cpu' supports float32 and float64, got {dtype}")
    if any(t.dtype != dtype for t in tensors):
        raise ValueError("render backend 'cpu': all field tensors must share one dtype, got "
                         + ", ".join(str(t.dtype) for t in tensors))
    if camera.width * camera.height > 2**31 - 1:
        raise ValueError(f"render backend 'cpu': image {camera.width}x{camera.height} is too large")
    with timed("projection"):
        proj = _Projection(field, camera)
    ids_t = torch.from_numpy(proj.ids)
    colors = field.colors.index_select(0, ids_t)
    if colors.dim() == 2:
        rgb_vis = colors
    else:   # SH: evaluated in torch (autograd to colours and, through the view direction, means)
        means_vis = field.means.index_select(0, ids_t) if colors.shape[1] > 1 else None   # degree 0: no direction
        rgb_vis = sh_rgb(colors, means_vis, torch.as_tensor(camera.center, dtype=dtype))
    means2d = torch.from_numpy(proj.means2d)
    if torch.is_grad_enabled() and field.means.requires_grad:   # as the reference's means2d
        means2d.requires_grad_(True)
    rgb, depth, feats, t_final = _FusedRender.apply(field.means, field.log_scales, field.quats,
                                                    field.opacity_logits, rgb_vis, field.features, means2d,
                                                    proj, tile_size)
    return (rgb, depth, feats if field.features is not None else None, t_final, means2d,
            torch.from_numpy(proj.radii), int(proj.ids.size))
