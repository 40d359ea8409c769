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


def _rotation(q: np.ndarray) -> np.ndarray:
    """(w, x, y, z) -> 3x3 rotation; zero quaternion -> identity."""
    if float(np.dot(q, q)) < 1e-12:
        return np.eye(3)
    w, x, y, z = q
    return Rotation.from_quat([x, y, z, w]).as_matrix()   # scipy: scalar-last, normalises


def _sh_basis(d: np.ndarray) -> np.ndarray:
    """The 16 real SH basis values of the 3DGS convention for a unit direction d."""
    x, y, z = d
    pi = math.pi
    c0 = 1.0 / (2.0 * math.sqrt(pi))
    c1 = math.sqrt(3.0 / (4.0 * pi))
    c2a, c2b, c2c = math.sqrt(15.0 / (4.0 * pi)), math.sqrt(5.0 / (16.0 * pi)), math.sqrt(15.0 / (16.0 * pi))
    c3a, c3b = math.sqrt(35.0 / (32.0 * pi)), math.sqrt(105.0 / (4.0 * pi))
    c3c, c3d, c3e = math.sqrt(21.0 / (32.0 * pi)), math.sqrt(7.0 / (16.0 * pi)), math.sqrt(105.0 / (16.0 * pi))
    return np.array([
        c0,
        -c1 * y, c1 * z, -c1 * x,
        c2a * x * y, -c2a * y * z, c2b * (2 * z * z - x * x - y * y), -c2a * x * z, c2c * (x * x - y * y),
        -c3a * y * (3 * x * x - y * y), c3b * x * y * z, -c3c * y * (4 * z * z - x * x - y * y),
        c3d * z * (2 * z * z - 3 * x * x - 3 * y * y), -c3c * x * (4 * z * z - x * x - y * y),
        c3e * z * (x * x - y * y), -c3a * x * (x * x - 3 * y * y),
    ])


def _colour(colors: np.ndarray, mean: np.ndarray, cam_center: np.ndarray) -> np.ndarray:
    if colors.ndim == 1:                       # RGB as given
        return colors
    k = colors.shape[0]                        # (K, 3) SH coefficients
    d = mean - cam_center
    d = d / math.sqrt(float(np.dot(d, d)) + 1e-20)
    return np.maximum(_sh_basis(d)[:k] @ colors + 0.5, 0.0)


def _project(field, camera) -> list[dict]:
    """Every Gaussian that survives the near/far and determinant rules, with its 2D footprint."""
    means, log_scales, quats = _np(field.means), _np(field.log_scales), _np(field.quats)
    logits, colors, feats = _np(field.opacity_logits), _np(field.colors), _np(field.features)
    K = np.asarray(camera.K, dtype=np.float64)
    w2c = np.asarray(camera.world_to_camera, dtype=np.float64)
    W, H = camera.width, camera.height
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    R, t = w2c[:3, :3], w2c[:3, 3]
    cam_center = -R.T @ t
    tan_x, tan_y = 0.5 * W / fx, 0.5 * H / fy
    out = []
    for i in range(means.shape[0]):
        pc = R @ means[i] + t
        x, y, z = pc
        if not np.all(np.isfinite(pc)) or not (NEAR_PLANE <= z <= FAR_PLANE):
            continue
        rot = _rotation(quats[i])
        s = np.exp(np.clip(log_scales[i], -30.0, 30.0))
        cov_world = rot @ np.diag(s * s) @ rot.T
        cov_cam = R @ cov_world @ R.T
        # clamp the direction used by the Jacobian (not the centre)
        xz = min(max(x / z, -(cx / fx + FOV_CLAMP_MARGIN * tan_x)), (W - cx) / fx + FOV_CLAMP_MARGIN * tan_x)
        yz = min(max(y / z, -(cy / fy + FOV_CLAMP_MARGIN * tan_y)), (H - cy) / fy + FOV_CLAMP_MARGIN * tan_y)
        J = np.array([[fx / z, 0.0, -fx * xz / z],
                      [0.0, fy / z, -fy * yz / z]])
        cov2 = J @ cov_cam @ J.T + EPS2D * np.eye(2)
        det = float(np.linalg.det(cov2))
        if not (np.isfinite(det) and det > 0):
            continue
        out.append({
            "index": i, "z": float(z),
            "uv": np.array([fx * x / z + cx, fy * y / z + cy]),
            "inv_cov": np.linalg.inv(cov2),
            "opacity": float(expit(logits[i])),
            "rgb": _colour(colors[i], means[i], cam_center),
            "feat": None if feats is None else feats[i],
        })
    out.sort(key=lambda g: (g["z"], g["index"]))   # depth order, ties by index
    return out


def _pixel(gaussians: list[dict], u: float, v: float, n_feat: int) -> tuple[np.ndarray, float, np.ndarray, float, list]:
    """Composite one pixel front to back. Returns rgb, depth, features, T and the raw terms seen."""
    T = 1.0
    rgb, depth, feat = np.zeros(3), 0.0, np.zeros(n_feat)
    seen = []                                    # (raw alpha, T after) for margin checks
    p = np.array([u, v])
    for g in gaussians:
        d = p - g["uv"]
        power = -0.5 * float(d @ g["inv_cov"] @ d)
        if power > 0:
            continue
        raw = g["opacity"] * math.exp(power)
        alpha = min(ALPHA_MAX, raw)
        if alpha < ALPHA_MIN:
            seen.append((raw, T))
            continue
        test_T = T * (1.0 - alpha)
        seen.append((raw, test_T))
        if test_T <= T_MIN:
            break
        w = alpha * T
        rgb += w * g["rgb"]
        depth += w * g["z"]
        if n_feat:
            feat += w * g["feat"]
        T = test_T
    return rgb, depth, feat, T, seen


def naive_render(field, camera, background=None, pixels: Optional[np.ndarray] = None) -> dict[str, np.ndarray]:
    """Render `field` from `camera` in float64, one pixel at a time.

    Returns rgb (H,W,3), depth (H,W), features (H,W,d) or None, alpha (H,W); with `pixels`
    (P x 2 integer (px, py)) the arrays are per listed pixel instead: (P,3), (P,), (P,d), (P,).
    """
    gaussians = _project(field, camera)
    n_feat = 0 if field.features is None else int(field.features.shape[1])
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
        c, dz, f, T, _ = _pixel(gaussians, x + 0.5, y + 0.5, n_feat)
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
    gaussians = _project(field, camera)
    n_feat = 0 if field.features is None else int(field.features.shape[1])
    m_lo, m_hi, m_t = math.inf, math.inf, math.inf
    for y in range(camera.height):
        for x in range(camera.width):
            *_, seen = _pixel(gaussians, x + 0.5, y + 0.5, n_feat)
            for raw, t_after in seen:
                m_lo = min(m_lo, abs(raw - ALPHA_MIN))
                m_hi = min(m_hi, ALPHA_MAX - raw)
                if raw >= ALPHA_MIN:
                    m_t = min(m_t, t_after - T_MIN)
    K, w2c = np.asarray(camera.K), np.asarray(camera.world_to_camera)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    W, H = camera.width, camera.height
    m_clamp = math.inf
    for g in gaussians:
        pc = w2c[:3, :3] @ _np(field.means)[g["index"]] + w2c[:3, 3]
        xz, yz = pc[0] / pc[2], pc[1] / pc[2]
        lx = ((W - cx) / fx + FOV_CLAMP_MARGIN * 0.5 * W / fx, cx / fx + FOV_CLAMP_MARGIN * 0.5 * W / fx)
        ly = ((H - cy) / fy + FOV_CLAMP_MARGIN * 0.5 * H / fy, cy / fy + FOV_CLAMP_MARGIN * 0.5 * H / fy)
        m_clamp = min(m_clamp, lx[0] - xz, xz + lx[1], ly[0] - yz, yz + ly[1])
    return {"alpha_min": m_lo, "alpha_max": m_hi, "t_min": m_t, "clamp": m_clamp}


def sh_basis(d: np.ndarray) -> np.ndarray:
    """Public access to the reference SH basis (tests check its orthonormality)."""
    return _sh_basis(np.asarray(d, dtype=np.float64))
