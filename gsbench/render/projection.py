"""EWA projection of 3D Gaussians into a camera (differentiable, plain PyTorch).

Shared by the `torch` and `cpu` backends: it is O(N) and vectorised, so the expensive part of
a render is the rasterization that follows it.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from gsbench.camera import Camera
from gsbench.gaussians import LOG_SCALE_MAX, LOG_SCALE_MIN, GaussianField, normalize_quats, quat_to_rotmat
from gsbench.render import rules


@dataclass
class Projected:
    """Projected Gaussians. Tensors are indexed by `ids` (the visible subset, in field order)."""

    ids: torch.Tensor        # (M,) long: indices into the field of the Gaussians that survived culling
    means2d: torch.Tensor    # (N, 2) all Gaussians (zeros for culled ones); grads land here
    conics: torch.Tensor     # (M, 3) inverse 2D covariance (a, b, c): [[a, b], [b, c]]
    depths: torch.Tensor     # (M,) camera-space z
    opacities: torch.Tensor  # (M,) sigmoid(opacity_logits)
    radii: torch.Tensor      # (N, 2) int pixel half-extent of the screen box (0 = culled)
    cov2d: torch.Tensor      # (M, 3) 2D covariance with low-pass (xx, xy, yy)


def camera_tensors(camera: Camera, device, dtype) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    K, w2c, _ = camera.device_tensors(device, dtype)
    return w2c[:3, :3], w2c[:3, 3], K


def _cov2d(means_c: torch.Tensor, rot: torch.Tensor, scales: torch.Tensor, R_wc: torch.Tensor,
           K: torch.Tensor, width: int, height: int) -> tuple[torch.Tensor, torch.Tensor]:
    """2D covariance (xx, xy, yy) with the low-pass added, and its determinant.

    The covariance is A A^T + EPS2D I with A = J R_wc R S (2x3). Its determinant is computed as
    det(A A^T) + EPS2D tr(A A^T) + EPS2D^2 with det(A A^T) = sum of the squared 2x2 minors of A
    (Cauchy-Binet): a sum of non-negative terms in which each minor is s_i s_j times a minor of the
    well-conditioned J R_wc R. So it never cancels, even in float32 for aspect ratios of 1e4 where
    xx * yy - xy^2 loses every digit.
    """
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    x, y, z = means_c.unbind(-1)
    tan_fovx = 0.5 * width / fx
    tan_fovy = 0.5 * height / fy
    lim_x_pos = (width - cx) / fx + rules.FOV_CLAMP_MARGIN * tan_fovx
    lim_x_neg = cx / fx + rules.FOV_CLAMP_MARGIN * tan_fovx
    lim_y_pos = (height - cy) / fy + rules.FOV_CLAMP_MARGIN * tan_fovy
    lim_y_neg = cy / fy + rules.FOV_CLAMP_MARGIN * tan_fovy
    inv_z = 1.0 / z
    tx = z * torch.minimum(torch.maximum(x * inv_z, -lim_x_neg), lim_x_pos)
    ty = z * torch.minimum(torch.maximum(y * inv_z, -lim_y_neg), lim_y_pos)
    zero = torch.zeros_like(z)
    J = torch.stack([
        fx * inv_z, zero, -fx * tx * inv_z * inv_z,
        zero, fy * inv_z, -fy * ty * inv_z * inv_z,
    ], dim=-1).reshape(-1, 2, 3)
    A = (J @ R_wc @ rot) * scales[:, None, :]          # J R_wc R S
    a0, a1 = A[:, 0], A[:, 1]
    xx, xy, yy = (a0 * a0).sum(-1), (a0 * a1).sum(-1), (a1 * a1).sum(-1)
    m01 = a0[:, 0] * a1[:, 1] - a0[:, 1] * a1[:, 0]
    m02 = a0[:, 0] * a1[:, 2] - a0[:, 2] * a1[:, 0]
    m12 = a0[:, 1] * a1[:, 2] - a0[:, 2] * a1[:, 1]
    det = (m01 * m01 + m02 * m02 + m12 * m12) + rules.EPS2D * (xx + yy) + rules.EPS2D * rules.EPS2D
    cov = torch.stack([xx + rules.EPS2D, xy, yy + rules.EPS2D], dim=-1)
    return cov, det


def project_gaussians(field: GaussianField, camera: Camera) -> Projected:
    """Project every Gaussian; cull by near/far plane, determinant, opacity and screen box."""
    device, dtype = field.means.device, field.means.dtype
    R_wc, t_wc, K = camera_tensors(camera, device, dtype)
    n = field.num
    W, H = camera.width, camera.height

    # Pass 1 (no grad): which Gaussians survive culling. Culled Gaussians never enter the graph,
    # so their gradients are exactly zero rather than NaN.
    with torch.no_grad():
        means_c = field.means @ R_wc.T + t_wc
        z = means_c[:, 2]
        ok = (z >= rules.NEAR_PLANE) & (z <= rules.FAR_PLANE) & torch.isfinite(means_c).all(-1)
        zs = torch.where(ok, z, torch.ones_like(z))
        mc = torch.where(ok[:, None], means_c, torch.ones_like(means_c))
        rot = quat_to_rotmat(normalize_quats(field.quats))
        cov, det = _cov2d(mc, rot, field.scales, R_wc, K, W, H)
        ok &= torch.isfinite(cov).all(-1) & torch.isfinite(det) & (det > 0)
        opac = field.opacity
        ok &= opac >= rules.ALPHA_MIN
        log_ratio = torch.log(torch.clamp(opac, min=rules.ALPHA_MIN) / rules.ALPHA_MIN)
        extend = torch.clamp(torch.sqrt(torch.clamp(2.0 * log_ratio, min=0.0)), max=rules.EXTEND_MAX)
        rx = torch.ceil(extend * torch.sqrt(torch.clamp(cov[:, 0], min=0.0)))
        ry = torch.ceil(extend * torch.sqrt(torch.clamp(cov[:, 2], min=0.0)))
        u = K[0, 0] * mc[:, 0] / zs + K[0, 2]
        v = K[1, 1] * mc[:, 1] / zs + K[1, 2]
        # screen box must overlap the image (pixel centres in [0.5, W-0.5])
        ok &= torch.isfinite(u) & torch.isfinite(v) & torch.isfinite(rx) & torch.isfinite(ry)
        ok &= (u + rx > 0) & (u - rx < W) & (v + ry > 0) & (v - ry < H)
        ok &= (rx > 0) & (ry > 0)
        ids = torch.nonzero(ok).squeeze(1)
        radii = torch.zeros(n, 2, dtype=torch.int64, device=device)
        radii[ids, 0] = torch.clamp(rx[ids], max=2**30).to(torch.int64)
        radii[ids, 1] = torch.clamp(ry[ids], max=2**30).to(torch.int64)

    # Pass 2 (differentiable) on the survivors only.
    means_c = field.means[ids] @ R_wc.T + t_wc
    z = means_c[:, 2]
    u = K[0, 0] * means_c[:, 0] / z + K[0, 2]
    v = K[1, 1] * means_c[:, 1] / z + K[1, 2]
    means2d = torch.zeros(n, 2, device=device, dtype=dtype).index_put((ids,), torch.stack([u, v], -1))
    if means2d.requires_grad:
        means2d.retain_grad()
    scales = torch.exp(field.log_scales[ids].clamp(LOG_SCALE_MIN, LOG_SCALE_MAX))
    rot = quat_to_rotmat(normalize_quats(field.quats[ids]))
    cov, det = _cov2d(means_c, rot, scales, R_wc, K, W, H)
    conics = torch.stack([cov[:, 2], -cov[:, 1], cov[:, 0]], -1) / det[:, None]
    return Projected(ids=ids, means2d=means2d, conics=conics, depths=z,
                     opacities=torch.sigmoid(field.opacity_logits[ids]), radii=radii, cov2d=cov)
