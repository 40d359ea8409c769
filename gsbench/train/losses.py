"""Training losses of the shared trainer and of GaussianDS (paper Sec. III-IV, docs/methods.md).

All image tensors are (H, W, C) or (H, W). Every division, sqrt and normalisation is guarded.
On the CPU, expected depth, scale_shift depth_loss, tv, sem and ds run `losses_cpu` (numba).

- `ssim`: differentiable SSIM (Gaussian window 11, sigma 1.5, zero padding as in 3DGS), mean over pixels/channels;
  on the CPU computed by `ssim_cpu` (numba, hand-written backward), elsewhere by `ssim_map`. Its constants are
  the one SSIM definition, gsbench/metrics/ssim_definition.py (the evaluation metric's too); the window's taps
  are computed here with torch, not taken from the metric's numpy `gaussian_window`, because the two exp
  implementations can differ in the last bit and these taps are the training numbers (tests check they agree).
- `reconstruction_loss`: L_rec = (1 - lambda) L1 + lambda (1 - SSIM).
- `solve_scale_shift`: closed-form least squares s, t with s * prior + t ~ target, in float64 on centred,
  magnitude-normalised data, no gradient; returns ok=False (the caller skips and counts) when the prior is
  (near) constant on the valid pixels or fewer than `min_valid` pixels are valid.
- `depth_loss`: the depth formulations `none | raw_l1 | minmax | scale_shift | pearson`, on the device
  without host synchronisation. A `disparity` prior is compared with the inverse rendered depth
  (1 / max(D, DEPTH_EPS)); `depth`/`metric` with D.
- `normalised_depth`: D divided by its detached alpha-weighted mean, so L_depth and L_tv are scale-free
  and the paper's lambdas weigh them the same on every scene (GaussianDS feeds this to both terms).
- `expected_depth`: D / alpha, the depth of the covered part of a pixel (a convex combination of the
  Gaussians' z, so it never blows up); L_depth compares the prior with it, not with D itself: 1 / D
  of a half-covered pixel reads as twice as near, so a disparity loss on D confounds coverage with
  depth and, once opacities are low (after an opacity reset), drives the opacities instead of the
  geometry (docs/training.md).
- `tv_loss`: isotropic TV sqrt(dx^2 + dy^2 + eps) averaged over pixels (the paper writes a sum; with
  lambda_tv = 1.5 a sum over pixels would dwarf every other term).
- `sem_loss`: mean |S_hat - S| over the pixels that have a target (and over the d channels).
- `depth_edges`: E_d = Canny on the (aligned) prior normalised to 8 bits over its valid pixels, optional dilation.
  Min-max normalisation to 8 bits makes E_d invariant to any alignment s * prior + t with s > 0, so
  E_d is computed once per view (tests check the invariance).
- `ds_loss`: mean |E_d * (S_hat - S)| over the pixels that have a target.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Optional

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from gsbench.metrics.ssim_definition import SSIM_C1, SSIM_C2, SSIM_SIGMA, SSIM_TRAIN_DEN_FLOOR, SSIM_WINDOW
from gsbench.train import losses_cpu as LC
from gsbench.train.ssim_cpu import ssim_mean_cpu

DEPTH_FORMULATIONS = ("none", "raw_l1", "minmax", "scale_shift", "pearson")
DEPTH_EPS = 1e-6          # rendered depth below this is "no surface" (not inverted, not used)
ALPHA_EPS = 1e-3          # accumulated alpha below this is "not covered" (1 - T in float32 is exact to ~1e-7)
CONSTANT_REL_EPS = 1e-9   # prior whose std is below this fraction of its magnitude is "constant"
#: False forces the PyTorch code below (the reference that tests compare `losses_cpu` with)
CPU_KERNELS = True


def _cpu_kernels(*ts: torch.Tensor) -> bool:
    """Whether `losses_cpu` takes these: non-empty CPU tensors of one float dtype and one shape."""
    t0 = ts[0]
    if not CPU_KERNELS or t0.dtype not in (torch.float32, torch.float64) or t0.numel() == 0:
        return False
    for t in ts:
        if t.device.type != "cpu" or t.dtype != t0.dtype or t.shape != t0.shape:
            return False
    return True


def _cpu_masks(shape: torch.Size, *masks: torch.Tensor) -> bool:
    """Whether these are bool CPU masks of this shape."""
    return all(m.dtype == torch.bool and m.device.type == "cpu" and m.shape == shape for m in masks)


# ---------------------------------------------------------------------------- SSIM / reconstruction
def _gaussian_1d(size: int, sigma: float, device, dtype) -> torch.Tensor:
    x = torch.arange(size, device=device, dtype=torch.float64) - (size - 1) / 2.0
    g = torch.exp(-(x * x) / (2.0 * sigma * sigma))
    return (g / g.sum()).to(dtype)


def _gaussian_window(size: int, sigma: float, channels: int, device, dtype) -> torch.Tensor:
    """The 2D window (C, 1, size, size) = outer product of the 1D Gaussian (reference for tests)."""
    g = _gaussian_1d(size, sigma, device, torch.float64)
    return (g[:, None] @ g[None, :]).to(dtype).expand(channels, 1, size, size).contiguous()


def _blur(x: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
    """Separable Gaussian filter of (1, C, H, W) with zero padding: equal to the 2D window, ~5x cheaper."""
    c, k = x.shape[1], g.numel()
    pad = k // 2
    x = F.conv2d(x, g.reshape(1, 1, 1, k).expand(c, 1, 1, k), padding=(0, pad), groups=c)
    return F.conv2d(x, g.reshape(1, 1, k, 1).expand(c, 1, k, 1), padding=(pad, 0), groups=c)


def ssim(img1: torch.Tensor, img2: torch.Tensor, window_size: int = SSIM_WINDOW,
         sigma: float = SSIM_SIGMA) -> torch.Tensor:
    """Mean SSIM of two (H, W, C) images in [0, 1]; differentiable (training loss, not the metric).

    Non-empty CPU images of one float dtype take `ssim_cpu` (the same function: numba, with a
    hand-written backward, about 2x faster than the convolutions); others the PyTorch `ssim_map`.
    """
    if (img1.shape == img2.shape and img1.dim() in (2, 3) and img1.numel() > 0
            and img1.device.type == "cpu" and img2.device.type == "cpu"
            and img1.dtype == img2.dtype and img1.dtype in (torch.float32, torch.float64)):
        a, b = (img1[..., None], img2[..., None]) if img1.dim() == 2 else (img1, img2)
        return ssim_mean_cpu(a, b, _gaussian_1d(window_size, sigma, "cpu", torch.float64).numpy(), SSIM_C1, SSIM_C2)
    return ssim_map(img1, img2, window_size, sigma).mean()


def ssim_map(img1: torch.Tensor, img2: torch.Tensor, window_size: int = SSIM_WINDOW,
             sigma: float = SSIM_SIGMA) -> torch.Tensor:
    """Per-pixel SSIM (1, C, H, W) with zero padding ('same' size, as the 3DGS training loss)."""
    if img1.shape != img2.shape:
        raise ValueError(f"ssim: shapes differ {tuple(img1.shape)} vs {tuple(img2.shape)}")
    if img1.dim() == 2:
        img1, img2 = img1[..., None], img2[..., None]
    c = img1.shape[-1]
    a = img1.permute(2, 0, 1)[None]
    b = img2.permute(2, 0, 1)[None]
    g = _gaussian_1d(window_size, sigma, a.device, a.dtype)
    stats = _blur(torch.cat([a, b, a * a, b * b, a * b], dim=1), g)      # one batched filter pass
    mu1, mu2, e11, e22, e12 = stats.split(c, dim=1)
    mu1_sq, mu2_sq, mu12 = mu1 * mu1, mu2 * mu2, mu1 * mu2
    s1, s2, s12 = e11 - mu1_sq, e22 - mu2_sq, e12 - mu12
    num = (2 * mu12 + SSIM_C1) * (2 * s12 + SSIM_C2)
    den = (mu1_sq + mu2_sq + SSIM_C1) * (s1 + s2 + SSIM_C2)   # >= C1 * C2 > 0 up to rounding
    return num / den.clamp_min(SSIM_TRAIN_DEN_FLOOR)


def l1(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return (a - b).abs().mean()


def reconstruction_loss(pred: torch.Tensor, gt: torch.Tensor, lambda_dssim: float = 0.2) -> torch.Tensor:
    """L_rec = (1 - lambda) L1 + lambda (1 - SSIM) (3DGS)."""
    return (1.0 - lambda_dssim) * l1(pred, gt) + lambda_dssim * (1.0 - ssim(pred, gt))


# ---------------------------------------------------------------------------- depth
@dataclass
class ScaleShift:
    s: float
    t: float
    ok: bool
    reason: str = ""
    n_valid: int = 0


def solve_scale_shift(prior: np.ndarray | torch.Tensor, target: np.ndarray | torch.Tensor,
                      valid: Optional[np.ndarray | torch.Tensor] = None, min_valid: int = 10) -> ScaleShift:
    """argmin_{s,t} sum_valid (s * prior + t - target)^2 in closed form (float64, centred, no gradient).

    Both inputs are divided by their largest valid magnitude first, so huge magnitudes neither overflow
    nor lose precision; s is scaled back at the end. Returns ok=False with a reason when fewer than
    `min_valid` finite valid pixels remain or the prior is (near) constant on them.
    """
    x = _np64(prior).reshape(-1)
    y = _np64(target).reshape(-1)
    m = np.isfinite(x) & np.isfinite(y)
    if valid is not None:
        m &= _np_bool(valid).reshape(-1)
    n = int(m.sum())
    if n < max(2, int(min_valid)):
        return ScaleShift(1.0, 0.0, False, f"{n} valid pixels (< {min_valid})", n)
    x, y = x[m], y[m]
    ax = float(np.max(np.abs(x)))
    ay = float(np.max(np.abs(y)))
    if ax == 0.0:
        return ScaleShift(1.0, 0.0, False, "prior is constant (all zero)", n)
    ay = ay if ay > 0.0 else 1.0
    xs, ys = x / ax, y / ay
    xm, ym = float(xs.mean()), float(ys.mean())
    xc, yc = xs - xm, ys - ym
    var = float(np.dot(xc, xc))
    if not np.isfinite(var) or var <= (CONSTANT_REL_EPS ** 2) * n * max(1.0, xm * xm):
        return ScaleShift(1.0, 0.0, False, "prior is (near) constant on the valid pixels", n)
    s_n = float(np.dot(xc, yc)) / var
    t_n = ym - s_n * xm
    s = s_n * ay / ax
    t = t_n * ay
    if not (np.isfinite(s) and np.isfinite(t)):
        return ScaleShift(1.0, 0.0, False, "non-finite scale/shift", n)
    return ScaleShift(s, t, True, "", n)


def _np64(a) -> np.ndarray:
    if isinstance(a, torch.Tensor):
        a = a.detach().cpu().numpy()
    return np.asarray(a, dtype=np.float64)


def _np_bool(a) -> np.ndarray:
    if isinstance(a, torch.Tensor):
        a = a.detach().cpu().numpy()
    return np.asarray(a, dtype=bool)


def render_space_depth(depth: torch.Tensor, kind: str) -> tuple[torch.Tensor, torch.Tensor]:
    """The rendered depth in the prior's space and where it is usable.

    `disparity` priors are compared with 1 / D (guarded: pixels with D <= DEPTH_EPS are not used and
    their inverse is computed from a clamped value, so no inf/NaN reaches the graph).
    """
    usable = depth > DEPTH_EPS
    if kind == "disparity":
        return 1.0 / depth.clamp_min(DEPTH_EPS), usable
    if kind in ("depth", "metric"):
        return depth, usable
    raise ValueError(f"unknown depth prior kind {kind!r} (disparity | depth | metric)")


@dataclass
class DepthTerm:
    """L_depth of one view. `loss` is a 0-dim tensor (0 where skipped) and `ok` a 0-dim bool tensor:
    both stay on the device, so the caller counts skips without a host synchronisation."""
    loss: Optional[torch.Tensor]   # None only for formulation 'none'
    ok: torch.Tensor
    s: torch.Tensor
    t: torch.Tensor
    n_valid: Optional[torch.Tensor] = None
    min_valid: int = 10

    @property
    def reason(self) -> str:
        """Why the term was skipped ('' when not): for diagnostics and tests; reading it synchronises."""
        if self.loss is None:
            return "formulation none"
        if bool(self.ok):
            return ""
        n = int(self.n_valid) if self.n_valid is not None else 0
        if n < max(2, self.min_valid):
            return f"{n} valid pixels (< {self.min_valid})"
        return "prior is (near) constant on the valid pixels"


def normalised_depth(depth: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
    """The rendered depth divided by its own alpha-weighted mean (detached): scale-free, so L_depth
    and L_tv mean the same on a scene and on the same scene scaled by any factor."""
    ref = depth.detach().sum() / alpha.detach().sum().clamp_min(1e-6)
    return depth / ref.clamp_min(DEPTH_EPS)


def expected_depth(depth: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
    """D / alpha where alpha > ALPHA_EPS, 0 (unusable for the depth loss) elsewhere: the depth of the
    covered part of each pixel, invariant to the opacities when one surface covers it."""
    if _cpu_kernels(depth, alpha):
        return LC.expected_depth_cpu(depth, alpha, ALPHA_EPS)
    covered = alpha > ALPHA_EPS
    return torch.where(covered, depth / alpha.clamp_min(ALPHA_EPS), torch.zeros_like(depth))


def _masked_mean(x: torch.Tensor, w: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
    return (x * w).sum() / n.clamp_min(1.0)


def depth_loss(formulation: str, depth: torch.Tensor, prior: np.ndarray | torch.Tensor,
               prior_valid: np.ndarray | torch.Tensor, kind: str, min_valid: int = 10) -> DepthTerm:
    """L_depth of one view under a formulation, without host synchronisation: masked sums instead of
    boolean indexing; a view with fewer than `min_valid` usable pixels or a (near) constant prior has
    ok=False and loss 0 (every branch stays finite, so no NaN gradient leaks through the mask)."""
    if formulation not in DEPTH_FORMULATIONS:
        raise ValueError(f"unknown depth formulation {formulation!r}; choose one of {', '.join(DEPTH_FORMULATIONS)}")
    dev = depth.device
    one, zero = torch.ones((), device=dev), torch.zeros((), device=dev)
    if formulation == "none":
        return DepthTerm(None, torch.zeros((), dtype=torch.bool, device=dev), one, zero)
    p = prior if isinstance(prior, torch.Tensor) else torch.as_tensor(np.asarray(prior, dtype=np.float32))
    p = p.to(device=dev, dtype=depth.dtype)
    pv = prior_valid if isinstance(prior_valid, torch.Tensor) else torch.as_tensor(_np_bool(prior_valid))
    if (formulation == "scale_shift" and kind in ("disparity", "depth", "metric") and _cpu_kernels(depth, p)
            and _cpu_masks(depth.shape, pv) and not p.requires_grad):
        loss, ok, s, t, n = LC.scale_shift_loss_cpu(depth, p, pv, kind == "disparity", DEPTH_EPS, min_valid,
                                                    CONSTANT_REL_EPS)
        return DepthTerm(loss, ok, s, t, n, int(min_valid))
    r, usable = render_space_depth(depth, kind)
    m = usable.detach() & pv.to(dev) & torch.isfinite(p)
    w = m.to(depth.dtype)
    n = w.sum()
    ok = n >= max(2, int(min_valid))
    p0 = torch.where(m, p, torch.zeros_like(p))
    r0 = torch.where(m, r, torch.zeros_like(r))
    s, t = one, zero
    if formulation == "raw_l1":
        loss = _masked_mean((r0 - p0).abs(), w, n)
    elif formulation == "scale_shift":
        s, t, good = _scale_shift_masked(p0, r0.detach(), m, n)
        ok = ok & good
        loss = _masked_mean((r0 - (s.to(r.dtype) * p0 + t.to(r.dtype))).abs(), w, n)
    elif formulation == "minmax":
        big = torch.finfo(p.dtype).max
        pmin, pmax = torch.where(m, p, big).amin(), torch.where(m, p, -big).amax()
        rd = r0.detach()
        rmin, rmax = torch.where(m, rd, big).amin(), torch.where(m, rd, -big).amax()
        span = pmax - pmin
        ok = ok & (span > CONSTANT_REL_EPS * torch.clamp_min(pmax.abs(), 1.0))
        span = torch.where(ok, span, one)
        rspan = torch.where(ok, (rmax - rmin).clamp_min(1e-12), one)
        pmin, rmin = torch.where(ok, pmin, zero), torch.where(ok, rmin, zero)
        loss = _masked_mean(((r0 - rmin) / rspan - (p0 - pmin) / span).abs(), w, n)
    else:   # pearson: 1 - correlation
        nn_ = n.clamp_min(1.0)
        pc = (p0 - (p0 * w).sum() / nn_) * w
        pstd = torch.sqrt((pc * pc).sum() / nn_)
        pmax = torch.where(m, p.abs(), zero).amax()
        ok = ok & (pstd > CONSTANT_REL_EPS * torch.clamp_min(pmax, 1.0))
        pstd = torch.where(ok, pstd, one)
        rc = (r0 - (r0 * w).sum() / nn_) * w
        rstd = torch.sqrt((rc * rc).sum() / nn_ + 1e-20)
        loss = 1.0 - (rc * pc).sum() / nn_ / (rstd * pstd)
    loss = torch.where(ok, loss, torch.zeros_like(loss))
    return DepthTerm(loss, ok, s, t, n, int(min_valid))


def _scale_shift_masked(x: torch.Tensor, y: torch.Tensor, m: torch.Tensor, n: torch.Tensor):
    """`solve_scale_shift` on the device: float64, magnitude-normalised, masked; (s, t, ok) tensors."""
    w = m.to(torch.float64)
    x, y = x.to(torch.float64), y.to(torch.float64)
    nn_ = n.to(torch.float64).clamp_min(1.0)
    ax = (x.abs() * w).amax()
    ay = (y.abs() * w).amax()
    ok = ax > 0
    ax = torch.where(ok, ax, torch.ones_like(ax))
    ay = torch.where(ay > 0, ay, torch.ones_like(ay))
    xs, ys = x / ax, y / ay
    xm, ym = (xs * w).sum() / nn_, (ys * w).sum() / nn_
    xc, yc = (xs - xm) * w, (ys - ym) * w
    var = (xc * xc).sum()
    ok = ok & torch.isfinite(var) & (var > (CONSTANT_REL_EPS ** 2) * nn_ * torch.clamp_min(xm * xm, 1.0))
    s_n = (xc * yc).sum() / torch.where(ok, var, torch.ones_like(var))
    t_n = ym - s_n * xm
    s, t = s_n * ay / ax, t_n * ay
    ok = ok & torch.isfinite(s) & torch.isfinite(t)
    return torch.where(ok, s, torch.ones_like(s)), torch.where(ok, t, torch.zeros_like(t)), ok


def tv_loss(depth: torch.Tensor, eps: float = 1e-6) -> torch.Tensor:
    """Isotropic TV of a (H, W) map: mean over pixels of sqrt(dx^2 + dy^2 + eps) (forward differences)."""
    if depth.shape[0] < 2 or depth.shape[1] < 2:
        return depth.sum() * 0.0
    if depth.dim() == 2 and _cpu_kernels(depth):
        return LC.tv_cpu(depth, eps)
    dx = depth[:-1, 1:] - depth[:-1, :-1]
    dy = depth[1:, :-1] - depth[:-1, :-1]
    return torch.sqrt((dx * dx + dy * dy + eps).clamp_min(1e-30)).mean()   # eps = 0: no NaN gradient at 0


# ---------------------------------------------------------------------------- semantics
def sem_loss(s_hat: torch.Tensor, target: torch.Tensor, has_target: torch.Tensor) -> torch.Tensor:
    """mean |S_hat - S| over pixels with a target (and channels), as a masked sum (no host sync);
    0 when no pixel has one: the caller knows that per view up front and counts the skip."""
    if s_hat.dim() >= 1 and _cpu_kernels(s_hat, target) and _cpu_masks(s_hat.shape[:-1], has_target):
        return LC.masked_abs_mean_cpu(s_hat, target, has_target)
    w = has_target.to(s_hat.dtype)[..., None]
    n = w.sum() * s_hat.shape[-1]
    return ((s_hat - target).abs() * w).sum() / n.clamp_min(1.0)


DS_AVERAGES = ("pixels", "edges")


def ds_loss(s_hat: torch.Tensor, target: torch.Tensor, has_target: torch.Tensor, edges: torch.Tensor,
            average: str = "pixels") -> torch.Tensor:
    """|E_d * (S_hat - S)| summed, then averaged over the pixels with a target (``pixels``, the default)
    or over the edge pixels with a target (``edges``: the same scale as L_sem, whatever share of
    the image the edges cover). E_d (H, W) in {0, 1}; 0 when no pixel counts."""
    if average not in DS_AVERAGES:
        raise ValueError(f"average must be one of {DS_AVERAGES}, got {average!r}")
    if s_hat.dim() >= 1 and _cpu_kernels(s_hat, target) and _cpu_masks(s_hat.shape[:-1], has_target, edges):
        return LC.masked_abs_mean_cpu(s_hat, target, has_target, edges, average == "edges")
    w = has_target.to(s_hat.dtype)[..., None]
    we = edges.to(s_hat.dtype)[..., None] * w
    n = (we if average == "edges" else w).sum() * s_hat.shape[-1]
    return ((s_hat - target).abs() * we).sum() / n.clamp_min(1.0)


def to_uint8_minmax(values: np.ndarray, valid: np.ndarray) -> Optional[np.ndarray]:
    """Min-max normalise the valid pixels to 0..255 (invalid -> 0); None if (near) constant."""
    v = np.asarray(values, dtype=np.float64)
    m = np.asarray(valid, dtype=bool) & np.isfinite(v)
    if m.sum() < 2:
        return None
    lo, hi = float(v[m].min()), float(v[m].max())
    if hi - lo <= CONSTANT_REL_EPS * max(1.0, abs(hi), abs(lo)):
        return None
    out = np.zeros(v.shape, dtype=np.float64)
    out[m] = (v[m] - lo) / (hi - lo) * 255.0
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


#: E_d covering a smaller share of a view's pixels than this counts as empty: L_ds then acts on a few
#: dozen pixels of a 256x192 view (fewer than one in a thousand), too few to move a boundary metric
EDGE_FLOOR = 1e-3


def edge_coverage(edges: Mapping[Any, np.ndarray], floor: float = EDGE_FLOOR) -> tuple[float, int]:
    """(mean share of pixels E_d marks over the views, number of views whose share is below `floor`);
    (0.0, 0) for no views."""
    arrays = [np.asarray(e, dtype=bool) for e in edges.values()]
    shares = [float(a.mean()) if a.size else 0.0 for a in arrays]
    if not shares:
        return 0.0, 0
    return float(np.mean(shares)), sum(sh < floor for sh in shares)


def depth_edges(values: np.ndarray, valid: np.ndarray, low: float = 50, high: float = 150,
                dilate: int = 1, size: int | None = None) -> np.ndarray:
    """E_d: Canny edges of the depth prior normalised to 8 bits, restricted to valid pixels (bool H x W).

    Edges that only mark the border of the invalid region are removed (valid mask eroded by one pixel
    before masking). `dilate` = number of 3x3 dilation passes (0 = none). `size` (gaussiands.edges.size):
    the short side in pixels at which Canny runs when the prior is larger (the prior is area-averaged
    over its valid pixels down to it, and the edges are scaled back by nearest neighbour), so E_d's
    share of the pixels does not shrink as 1 / resolution; None = at the prior's own size.
    """
    values = np.asarray(values)
    finite = np.asarray(valid, dtype=bool) & np.isfinite(values.astype(np.float64))   # NaN/inf = invalid
    H, W = values.shape[:2]
    if size is None or min(H, W) <= int(size):
        return _edges_here(values, finite, low, high, dilate)
    scale = int(size) / min(H, W)
    w, h = max(1, round(W * scale)), max(1, round(H * scale))
    num = cv2.resize(np.where(finite, values, 0.0).astype(np.float64), (w, h), interpolation=cv2.INTER_AREA)
    den = cv2.resize(finite.astype(np.float64), (w, h), interpolation=cv2.INTER_AREA)
    small = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    e = _edges_here(small, den > 0.5, low, high, dilate)
    return (cv2.resize(e.astype(np.uint8), (W, H), interpolation=cv2.INTER_NEAREST) > 0) & finite


def _edges_here(values: np.ndarray, finite: np.ndarray, low: float, high: float, dilate: int) -> np.ndarray:
    """`depth_edges` at the prior's own size; `finite` = valid and finite."""
    img = to_uint8_minmax(values, finite)
    if img is None:
        return np.zeros(finite.shape, dtype=bool)
    e = cv2.Canny(img, float(low), float(high)) > 0
    m = finite
    if not m.all():
        m = cv2.erode(m.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    e &= m
    if dilate > 0:
        e = cv2.dilate(e.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=int(dilate)) > 0
        e &= finite
    return e
