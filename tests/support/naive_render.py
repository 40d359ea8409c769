"""A deliberately naive float64 Gaussian-splatting renderer: the independent reference for tests.

Written from the rules in gsbench/render/rules.py (restated below), NOT from projection.py or the
backends: rotations come from scipy, the spherical-harmonic constants are computed from their
closed forms, and every pixel walks ALL Gaussians in depth order one at a time. It is slow on
purpose; use `pixels=` to evaluate a subset of pixels of a large image.

Rules (shared by every backend):
  - pixel (px, py) is sampled at (px + 0.5, py + 0.5) in u = fx x/z + cx, v = fy y/z + cy;
  - Gaussians with camera z outside [NEAR_PLANE, FAR_PLANE] (or non-finite) are dropped;
  - EWA: the Jacobian of (u, v) is taken at x/z, y/z clamped to the image extent plus
    FOV_CLAMP_MARGIN * tan(fov/2) per side; EPS2D * I is added to the 2D covariance; a Gaussian
    whose 2D determinant is not finite and > 0 is dropped;
  - alpha = min(ALPHA_MAX, opacity * exp(power)); skipped where alpha < ALPHA_MIN or power > 0;
  - front to back by camera z (ties by index); a pixel stops before the Gaussian that would bring
    its transmittance to T_MIN or below;
  - quaternion (w, x, y, z) normalised, a zero quaternion (|q|^2 < 1e-12) is the identity;
    scales = exp(clip(log_scales, -30, 30)); opacity = sigmoid(logit);
  - SH colours: 3DGS real SH basis up to degree 3, direction camera centre -> mean, + 0.5,
    clamped at 0 from below; RGB colours are used as given.
Outputs: rgb (+ T * background), depth = sum w z, features = sum w f, alpha = 1 - T.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.special import expit

NEAR_PLANE = 0.01
FAR_PLANE = 1e10
EPS2D = 0.3
ALPHA_MAX = 0.999
ALPHA_MIN = 1.0 / 255.0
T_MIN = 1e-4
FOV_CLAMP_MARGIN = 0.3


def _np(t) -> Optional[np.ndarray]:
    if t is None:
        return None
    if hasattr(t, "detach"):
        t = t.detach().cpu().double().numpy()
    return np.asarray(t, dtype=np.float64)


def _rotations(q: np.ndarray) -> np.ndarray:
    """(N, 4) (w, x, y, z) -> (N, 3, 3) rotations; zero quaternions -> identity."""
    out = np.tile(np.eye(3), (q.shape[0], 1, 1))
    ok = np.einsum("ij,ij->i", q, q) >= 1e-12
    if ok.any():
        w, x, y, z = q[ok].T
        out[ok] = Rotation.from_quat(np.stack([x, y, z, w], axis=1)).as_matrix()   # scalar-last; normalises
    return out


def _sh_basis(d: np.ndarray) -> np.ndarray:
    """The 16 real SH basis values of the 3DGS convention for unit directions d (..., 3)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    pi = math.pi
    c0 = 1.0 / (2.0 * math.sqrt(pi))
    c1 = math.sqrt(3.0 / (4.0 * pi))
    c2a, c2b, c2c = math.sqrt(15.0 / (4.0 * pi)), math.sqrt(5.0 / (16.0 * pi)), math.sqrt(15.0 / (16.0 * pi))
    c3a, c3b = math.sqrt(35.0 / (32.0 * pi)), math.sqrt(105.0 / (4.0 * pi))
    c3c, c3d, c3e = math.sqrt(21.0 / (32.0 * pi)), math.sqrt(7.0 / (16.0 * pi)), math.sqrt(105.0 / (16.0 * pi))
    return np.stack([
        c0 * np.ones_like(x),
        -c1 * y, c1 * z, -c1 * x,
        c2a * x * y, -c2a * y * z, c2b * (2 * z * z - x * x - y * y), -c2a * x * z, c2c * (x * x - y * y),
        -c3a * y * (3 * x * x - y * y), c3b * x * y * z, -c3c * y * (4 * z * z - x * x - y * y),
        c3d * z * (2 * z * z - 3 * x * x - 3 * y * y), -c3c * x * (4 * z * z - x * x - y * y),
        c3e * z * (x * x - y * y), -c3a * x * (x * x - 3 * y * y),
    ], axis=-1)


def _colours(colors: np.ndarray, means: np.ndarray, cam_center: np.ndarray) -> np.ndarray:
    if colors.ndim == 2:                       # (N, 3) RGB as given
        return colors
    k = colors.shape[1]                        # (N, K, 3) SH coefficients
    d = means - cam_center
    d = d / np.sqrt(np.sum(d * d, axis=1, keepdims=True) + 1e-20)
    return np.maximum(np.einsum("nk,nkc->nc", _sh_basis(d)[:, :k], colors) + 0.5, 0.0)


def _project(field, camera) -> dict[str, np.ndarray]:
    """Every Gaussian that survives the near/far and determinant rules, with its 2D footprint,
    sorted front to back (ties by index)."""
    means, log_scales, quats = _np(field.means), _np(field.log_scales), _np(field.quats)
    logits, colors, feats = _np(field.opacity_logits), _np(field.colors), _np(field.features)
    n = means.shape[0]
    if feats is None:
        feats = np.zeros((n, 0))
    K = np.asarray(camera.K, dtype=np.float64)
    w2c = np.asarray(camera.world_to_camera, dtype=np.float64)
    W, H = camera.width, camera.height
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    R, t = w2c[:3, :3], w2c[:3, 3]
    cam_center = -R.T @ t
    pc = np.einsum("ij,nj->ni", R, means) + t
    with np.errstate(all="ignore"):
        x, y, z = pc[:, 0], pc[:, 1], pc[:, 2]
        keep = np.all(np.isfinite(pc), axis=1) & (z >= NEAR_PLANE) & (z <= FAR_PLANE)
        keep_idx = np.nonzero(keep)[0]
        x, y, z = x[keep], y[keep], z[keep]
        rot = _rotations(quats[keep])
        s = np.exp(np.clip(log_scales[keep], -30.0, 30.0))
        cov_world = np.einsum("nij,nj,nkj->nik", rot, s * s, rot)           # R diag(s^2) R^T
        cov_cam = np.einsum("ij,njk,lk->nil", R, cov_world, R)
        # the Jacobian uses the clamped direction (not the centre)
        tan_x, tan_y = 0.5 * W / fx, 0.5 * H / fy
        xz = np.clip(x / z, -(cx / fx + FOV_CLAMP_MARGIN * tan_x), (W - cx) / fx + FOV_CLAMP_MARGIN * tan_x)
        yz = np.clip(y / z, -(cy / fy + FOV_CLAMP_MARGIN * tan_y), (H - cy) / fy + FOV_CLAMP_MARGIN * tan_y)
        J = np.zeros((len(z), 2, 3))
        J[:, 0, 0], J[:, 0, 2] = fx / z, -fx * xz / z
        J[:, 1, 1], J[:, 1, 2] = fy / z, -fy * yz / z
        cov2 = np.einsum("nij,njk,nlk->nil", J, cov_cam, J) + EPS2D * np.eye(2)
        det = cov2[:, 0, 0] * cov2[:, 1, 1] - cov2[:, 0, 1] * cov2[:, 1, 0]
        ok = np.isfinite(det) & (det > 0) & np.all(np.isfinite(cov2), axis=(1, 2))
    idx = keep_idx[ok]
    cov2, x, y, z = cov2[ok], x[ok], y[ok], z[ok]
    inv = np.empty_like(cov2)
    inv[:, 0, 0], inv[:, 1, 1] = cov2[:, 1, 1] / det[ok], cov2[:, 0, 0] / det[ok]
    inv[:, 0, 1] = inv[:, 1, 0] = -cov2[:, 0, 1] / det[ok]
    order = np.lexsort((idx, z))                                          # by z, then index
    return {
        "index": idx[order], "z": z[order],
        "uv": np.stack([fx * x / z + cx, fy * y / z + cy], axis=1)[order],
        "inv_cov": inv[order],
        "opacity": expit(logits[idx])[order],
        "rgb": _colours(colors[idx], means[idx], cam_center)[order],
        "feat": feats[idx][order],
    }


def _pixel(g: dict[str, np.ndarray], u: float, v: float) -> tuple[np.ndarray, float, np.ndarray, float, list]:
    """Composite one pixel front to back. Returns rgb, depth, features, T and the raw terms seen."""
    T = 1.0
    rgb, depth, feat = np.zeros(3), 0.0, np.zeros(g["feat"].shape[1])
    seen = []                                    # (raw alpha, T after) for margin checks
    d = np.array([u, v]) - g["uv"]               # (M, 2)
    with np.errstate(over="ignore", invalid="ignore"):
        power = -0.5 * np.einsum("mi,mij,mj->m", d, g["inv_cov"], d)
        raw_all = g["opacity"] * np.exp(np.minimum(power, 0.0))
    # walk the Gaussians in depth order; those with raw alpha < ALPHA_MIN / 10 or power > 0 are
    # skipped by the rules anyway, so the loop visits only the others
    for k in np.nonzero((power <= 0) & (raw_all >= 0.1 * ALPHA_MIN))[0]:
        raw = float(raw_all[k])
        alpha = min(ALPHA_MAX, raw)
        if alpha < ALPHA_MIN:
            if raw > 0.1 * ALPHA_MIN:
                seen.append((raw, T))
            continue
        test_T = T * (1.0 - alpha)
        seen.append((raw, test_T))
        if test_T <= T_MIN:
            break
        w = alpha * T
        rgb += w * g["rgb"][k]
        depth += w * g["z"][k]
        feat += w * g["feat"][k]
        T = test_T
    return rgb, depth, feat, T, seen


def naive_render(field, camera, background=None, pixels: Optional[np.ndarray] = None) -> dict[str, np.ndarray]:
    """Render `field` from `camera` in float64, one pixel at a time.

    Returns rgb (H,W,3), depth (H,W), features (H,W,d) or None, alpha (H,W); with `pixels`
    (P x 2 integer (px, py)) the arrays are per listed pixel instead: (P,3), (P,), (P,d), (P,).
    """
    g = _project(field, camera)
    n_feat = g["feat"].shape[1]
    W, H = camera.width, camera.height
    if pixels is None:
        py, px = np.mgrid[0:H, 0:W]
        pix = np.stack([px.ravel(), py.ravel()], axis=1)
    else:
        pix = np.asarray(pixels, dtype=np.int64).reshape(-1, 2)
    P = pix.shape[0]
    rgb, depth, feat, alpha = np.zeros((P, 3)), np.zeros(P), np.zeros((P, n_feat)), np.zeros(P)
    bg = None if background is None else _np(background).reshape(3)
    for k, (x, y) in enumerate(pix):
        c, dz, f, T, _ = _pixel(g, x + 0.5, y + 0.5)
        rgb[k] = c + (T * bg if bg is not None else 0.0)
        depth[k], feat[k], alpha[k] = dz, f, 1.0 - T
    shape = (H, W) if pixels is None else (P,)
    return {
        "rgb": rgb.reshape(shape + (3,)), "depth": depth.reshape(shape),
        "features": None if field.features is None else feat.reshape(shape + (n_feat,)),
        "alpha": alpha.reshape(shape),
    }


def threshold_margins(field, camera) -> dict[str, float]:
    """How close any pixel comes to a discontinuity of the rules (for gradcheck scene design).

    alpha_min: min |raw alpha - ALPHA_MIN|; alpha_max: min (ALPHA_MAX - raw alpha) (negative if
    clamped); t_min: min over composited terms of T_after - T_MIN (negative if a pixel stopped);
    clamp: min distance of a projected x/z, y/z from the EWA clamp limits (negative if clamped).
    """
    g = _project(field, camera)
    m_lo, m_hi, m_t = math.inf, math.inf, math.inf
    for y in range(camera.height):
        for x in range(camera.width):
            *_, seen = _pixel(g, x + 0.5, y + 0.5)
            for raw, t_after in seen:
                m_lo = min(m_lo, abs(raw - ALPHA_MIN))
                m_hi = min(m_hi, ALPHA_MAX - raw)
                if raw >= ALPHA_MIN:
                    m_t = min(m_t, t_after - T_MIN)
    K, w2c = np.asarray(camera.K), np.asarray(camera.world_to_camera)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    W, H = camera.width, camera.height
    m_clamp = math.inf
    for i in g["index"]:
        pc = w2c[:3, :3] @ _np(field.means)[i] + w2c[:3, 3]
        xz, yz = pc[0] / pc[2], pc[1] / pc[2]
        lx = ((W - cx) / fx + FOV_CLAMP_MARGIN * 0.5 * W / fx, cx / fx + FOV_CLAMP_MARGIN * 0.5 * W / fx)
        ly = ((H - cy) / fy + FOV_CLAMP_MARGIN * 0.5 * H / fy, cy / fy + FOV_CLAMP_MARGIN * 0.5 * H / fy)
        m_clamp = min(m_clamp, lx[0] - xz, xz + lx[1], ly[0] - yz, yz + ly[1])
    return {"alpha_min": m_lo, "alpha_max": m_hi, "t_min": m_t, "clamp": m_clamp}


def sh_basis(d: np.ndarray) -> np.ndarray:
    """Public access to the reference SH basis (tests check its orthonormality)."""
    return _sh_basis(np.asarray(d, dtype=np.float64))
