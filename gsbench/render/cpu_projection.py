"""Numba kernels of the `cpu` backend's projection: EWA projection with culling, and its hand-written backward.

The same mathematics and rules as the reference `project_gaussians` (gsbench/render/projection.py),
one Gaussian per loop iteration (numba prange): each Gaussian's values and gradients depend on that
Gaussian only, so there is no reduction and results are bit-identical for any thread count.

Camera-space points and projected centres come from the caller (working dtype, the reference's
operations); everything else is computed in float64 (one compiled specialisation; inputs are
converted, outputs are rounded to the working dtype by the caller). Per Gaussian (camera R, t, fx, fy, cx, cy):
    p = R m + t = (x, y, z);   u = fx x / z + cx,  v = fy y / z + cy          (means2d)
    s = exp(clamp(log_scales, -30, 30))      (no gradient outside the clamp, as torch.clamp)
    qn = q / |q|, or the identity with zero gradient when |q|^2 < QUAT_EPS
    tx = z clamp(x / z, -lim_x_neg, lim_x_pos) (likewise ty): the FOV clamp; while clamped, no
         gradient reaches x through it (tx = z * limit then)
    J = [[fx/z, 0, -fx tx/z^2], [0, fy/z, -fy ty/z^2]],  A = J R rot(qn) diag(s)  (2x3)
    xx, xy, yy = rows of A A^T;  m01, m02, m12 = 2x2 minors of A
    det = (m01^2 + m02^2 + m12^2) + EPS2D (xx + yy) + EPS2D^2   (Cauchy-Binet: never cancels)
    cov = (xx + EPS2D, xy, yy + EPS2D);  conic = (cov_yy, -cov_xy, cov_xx) / det
    opacity = sigmoid(logit);  depth channel = z
Culling (culled Gaussians get ok = False, radii 0 and zero gradients): z outside
[NEAR_PLANE, FAR_PLANE] or non-finite camera coordinates; covariance or determinant not finite
(in float64 or once rounded to the working dtype), or det <= 0; opacity < ALPHA_MIN (compared
in the working dtype, as the reference does); screen box (radius = ceil(extend sqrt(cov)) per
axis) off the image or of radius 0.

Parameter row layout (float64, shared by forward output and backward gradient input):
    P_U, P_V, P_CA, P_CB, P_CC, P_OP, P_Z
Camera array layout: R (row-major, 9), t (3), fx, fy, cx, cy, lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from gsbench.gaussians import LOG_SCALE_MAX, LOG_SCALE_MIN, QUAT_EPS
from gsbench.render import rules

P_U, P_V, P_CA, P_CB, P_CC, P_OP, P_Z = 0, 1, 2, 3, 4, 5, 6
NPROJ = 7
NCAM = 20

_NEAR = rules.NEAR_PLANE
_FAR = rules.FAR_PLANE
_EPS = rules.EPS2D
_AMIN = rules.ALPHA_MIN
_EXT = rules.EXTEND_MAX
_LSMIN = LOG_SCALE_MIN
_LSMAX = LOG_SCALE_MAX
_QEPS = QUAT_EPS
_RMAX = float(2**30)
_AMIN32 = float(np.float32(rules.ALPHA_MIN))

_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)


def camera_array(R, t, K, width: int, height: int) -> np.ndarray:
    """Camera constants in the layout the kernels read (float64), FOV clamp limits as projection.py."""
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    tan_fovx = 0.5 * width / fx
    tan_fovy = 0.5 * height / fy
    cam = np.empty(NCAM, np.float64)
    cam[0:9] = np.asarray(R, np.float64).reshape(9)
    cam[9:12] = np.asarray(t, np.float64).reshape(3)
    cam[12:16] = (fx, fy, cx, cy)
    cam[16] = cx / fx + rules.FOV_CLAMP_MARGIN * tan_fovx
    cam[17] = (width - cx) / fx + rules.FOV_CLAMP_MARGIN * tan_fovx
    cam[18] = cy / fy + rules.FOV_CLAMP_MARGIN * tan_fovy
    cam[19] = (height - cy) / fy + rules.FOV_CLAMP_MARGIN * tan_fovy
    return cam


@njit(inline="always", **_OPTS)
def _sigmoid(x):
    if x >= 0.0:
        return 1.0 / (1.0 + np.exp(-x))
    e = np.exp(x)
    return e / (1.0 + e)


@njit(inline="always", **_OPTS)
def _rot(qw, qx, qy, qz, rq):
    rq[0, 0] = 1.0 - 2.0 * (qy * qy + qz * qz)
    rq[0, 1] = 2.0 * (qx * qy - qw * qz)
    rq[0, 2] = 2.0 * (qx * qz + qw * qy)
    rq[1, 0] = 2.0 * (qx * qy + qw * qz)
    rq[1, 1] = 1.0 - 2.0 * (qx * qx + qz * qz)
    rq[1, 2] = 2.0 * (qy * qz - qw * qx)
    rq[2, 0] = 2.0 * (qx * qz - qw * qy)
    rq[2, 1] = 2.0 * (qy * qz + qw * qx)
    rq[2, 2] = 1.0 - 2.0 * (qx * qx + qy * qy)


@njit(inline="always", **_OPTS)
def _geometry(g, pc, log_scales, quats, cam, p, s, qn, rq, B, J, M, A):
    """Fill camera point p, scales s, unit quaternion qn, rotation rq, B = R rq, J, M = J B, A = M diag(s).

    Returns (qnorm, small, clamped_x, clamped_y, cx_val, cy_val): the quaternion norm, whether it was
    replaced by the identity, and whether (and to what value) x/z, y/z were clamped.
    """
    for r in range(3):
        p[r] = pc[g, r]
    for k in range(3):
        s[k] = np.exp(min(max(log_scales[g, k], _LSMIN), _LSMAX))
    n2 = quats[g, 0] * quats[g, 0] + quats[g, 1] * quats[g, 1] + quats[g, 2] * quats[g, 2] + quats[g, 3] * quats[g, 3]
    small = n2 < _QEPS
    if small:
        qnorm = 1.0
        qn[0] = 1.0
        qn[1] = 0.0
        qn[2] = 0.0
        qn[3] = 0.0
    else:
        qnorm = np.sqrt(n2)
        for k in range(4):
            qn[k] = quats[g, k] / qnorm
    _rot(qn[0], qn[1], qn[2], qn[3], rq)
    for r in range(3):
        for c in range(3):
            B[r, c] = cam[3 * r] * rq[0, c] + cam[3 * r + 1] * rq[1, c] + cam[3 * r + 2] * rq[2, c]
    x, y, z = p[0], p[1], p[2]
    fx, fy = cam[12], cam[13]
    rx = x / z
    ry = y / z
    cxv = min(max(rx, -cam[16]), cam[17])
    cyv = min(max(ry, -cam[18]), cam[19])
    clamped_x = not (rx >= -cam[16] and rx <= cam[17])
    clamped_y = not (ry >= -cam[18] and ry <= cam[19])
    tx = z * cxv
    ty = z * cyv
    J[0, 0] = fx / z
    J[0, 1] = 0.0
    J[0, 2] = -fx * tx / (z * z)
    J[1, 0] = 0.0
    J[1, 1] = fy / z
    J[1, 2] = -fy * ty / (z * z)
    for r in range(2):
        for c in range(3):
            M[r, c] = J[r, 0] * B[0, c] + J[r, 1] * B[1, c] + J[r, 2] * B[2, c]
            A[r, c] = M[r, c] * s[c]
    return qnorm, small, clamped_x, clamped_y, cxv, cyv


@njit(inline="always", **_OPTS)
def _cov(A):
    xx = A[0, 0] * A[0, 0] + A[0, 1] * A[0, 1] + A[0, 2] * A[0, 2]
    xy = A[0, 0] * A[1, 0] + A[0, 1] * A[1, 1] + A[0, 2] * A[1, 2]
    yy = A[1, 0] * A[1, 0] + A[1, 1] * A[1, 1] + A[1, 2] * A[1, 2]
    m01 = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    m02 = A[0, 0] * A[1, 2] - A[0, 2] * A[1, 0]
    m12 = A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]
    det = (m01 * m01 + m02 * m02 + m12 * m12) + _EPS * (xx + yy) + _EPS * _EPS
    return xx, xy, yy, m01, m02, m12, det


@njit(parallel=True, **_OPTS)
def project_forward(pc, uv, log_scales, quats, logits, cam, width, height, f32, ok, params, radii):
    """Project and cull every Gaussian: ok (N,) bool, params (N, NPROJ), radii (N, 2) int64 (0 if culled).

    pc (N, 3): camera-space points R m + t and uv (N, 2): projected centres, both computed by the
    caller with the reference's operations, in its order, in the working dtype (so depth order,
    depth channel and means2d equal the reference's bit for bit), given here as float64.
    """
    n = pc.shape[0]
    for g in prange(n):
        p = np.empty(3)
        s = np.empty(3)
        qn = np.empty(4)
        rq = np.empty((3, 3))
        B = np.empty((3, 3))
        J = np.empty((2, 3))
        M = np.empty((2, 3))
        A = np.empty((2, 3))
        ok[g] = False
        radii[g, 0] = 0
        radii[g, 1] = 0
        for k in range(NPROJ):
            params[g, k] = 0.0
        for r in range(3):
            p[r] = pc[g, r]
        z = p[2]
        if not (z >= _NEAR and z <= _FAR and np.isfinite(p[0]) and np.isfinite(p[1]) and np.isfinite(z)):
            continue
        _geometry(g, pc, log_scales, quats, cam, p, s, qn, rq, B, J, M, A)
        xx, xy, yy, m01, m02, m12, det = _cov(A)
        cxx = xx + _EPS
        cyy = yy + _EPS
        if not (np.isfinite(cxx) and np.isfinite(xy) and np.isfinite(cyy) and np.isfinite(det) and det > 0.0):
            continue
        if f32 and not (np.isfinite(np.float32(cxx)) and np.isfinite(np.float32(xy)) and np.isfinite(np.float32(cyy))
                        and np.isfinite(np.float32(det))):
            continue    # overflows the working dtype: the reference culls it
        op = _sigmoid(logits[g])
        opw = np.float64(np.float32(op)) if f32 else op
        if not (opw >= (_AMIN32 if f32 else _AMIN)):
            continue
        extend = min(np.sqrt(max(2.0 * np.log(max(op, _AMIN) / _AMIN), 0.0)), _EXT)
        rx = np.ceil(extend * np.sqrt(max(cxx, 0.0)))
        ry = np.ceil(extend * np.sqrt(max(cyy, 0.0)))
        u = uv[g, 0]
        v = uv[g, 1]
        if not (np.isfinite(u) and np.isfinite(v) and np.isfinite(rx) and np.isfinite(ry)):
            continue
        if not (u + rx > 0.0 and u - rx < width and v + ry > 0.0 and v - ry < height and rx > 0.0 and ry > 0.0):
            continue
        ok[g] = True
        radii[g, 0] = np.int64(min(rx, _RMAX))
        radii[g, 1] = np.int64(min(ry, _RMAX))
        params[g, P_U] = u
        params[g, P_V] = v
        params[g, P_CA] = cyy / det
        params[g, P_CB] = -xy / det
        params[g, P_CC] = cxx / det
        params[g, P_OP] = op
        params[g, P_Z] = z


@njit(parallel=True, **_OPTS)
def project_backward(ids, pc, log_scales, quats, logits, cam, grads, g_means, g_log_scales, g_quats, g_logits):
    """Gradients of the raw field tensors from gradients of the projected rows (`grads` (M, NPROJ),
    rows aligned with `ids`). Writes rows ids of the outputs (the others are left untouched: zero)."""
    m = ids.size
    for i in prange(m):
        g = ids[i]
        p = np.empty(3)
        s = np.empty(3)
        qn = np.empty(4)
        rq = np.empty((3, 3))
        B = np.empty((3, 3))
        J = np.empty((2, 3))
        M = np.empty((2, 3))
        A = np.empty((2, 3))
        dA = np.zeros((2, 3))
        dJ = np.zeros((2, 3))
        dR = np.zeros((3, 3))
        qnorm, small, clx, cly, cxv, cyv = _geometry(g, pc, log_scales, quats, cam, p, s, qn, rq, B, J, M, A)
        xx, xy, yy, m01, m02, m12, det = _cov(A)
        x, y, z = p[0], p[1], p[2]
        fx, fy = cam[12], cam[13]
        du = grads[i, P_U]
        dv = grads[i, P_V]
        dca = grads[i, P_CA]
        dcb = grads[i, P_CB]
        dcc = grads[i, P_CC]
        ca = (yy + _EPS) / det
        cb = -xy / det
        cc = (xx + _EPS) / det
        # conic = (cov_yy, -cov_xy, cov_xx) / det
        d_det = -(dca * ca + dcb * cb + dcc * cc) / det
        d_xx = dcc / det + _EPS * d_det
        d_yy = dca / det + _EPS * d_det
        d_xy = -dcb / det
        dm01 = 2.0 * m01 * d_det
        dm02 = 2.0 * m02 * d_det
        dm12 = 2.0 * m12 * d_det
        for k in range(3):
            dA[0, k] = 2.0 * d_xx * A[0, k] + d_xy * A[1, k]
            dA[1, k] = 2.0 * d_yy * A[1, k] + d_xy * A[0, k]
        # minor(i, j) = A0i A1j - A0j A1i
        dA[0, 0] += dm01 * A[1, 1]
        dA[1, 1] += dm01 * A[0, 0]
        dA[0, 1] -= dm01 * A[1, 0]
        dA[1, 0] -= dm01 * A[0, 1]
        dA[0, 0] += dm02 * A[1, 2]
        dA[1, 2] += dm02 * A[0, 0]
        dA[0, 2] -= dm02 * A[1, 0]
        dA[1, 0] -= dm02 * A[0, 2]
        dA[0, 1] += dm12 * A[1, 2]
        dA[1, 2] += dm12 * A[0, 1]
        dA[0, 2] -= dm12 * A[1, 1]
        dA[1, 1] -= dm12 * A[0, 2]
        # A = M diag(s), M = J B, B = R rq
        for k in range(3):
            ds = dA[0, k] * M[0, k] + dA[1, k] * M[1, k]
            ls = log_scales[g, k]
            g_log_scales[g, k] = ds * s[k] if (ls >= _LSMIN and ls <= _LSMAX) else 0.0
        for r in range(2):
            for c in range(3):
                acc = 0.0
                for k in range(3):
                    acc += dA[r, k] * s[k] * B[c, k]
                dJ[r, c] = acc
        for a in range(3):
            for k in range(3):
                acc = 0.0
                for c in range(3):
                    dB_ck = J[0, c] * dA[0, k] * s[k] + J[1, c] * dA[1, k] * s[k]
                    acc += cam[3 * c + a] * dB_ck
                dR[a, k] = acc
        # rotation matrix -> unit quaternion
        w, qx, qy, qz = qn[0], qn[1], qn[2], qn[3]
        dw = 2.0 * (-qz * dR[0, 1] + qy * dR[0, 2] + qz * dR[1, 0] - qx * dR[1, 2] - qy * dR[2, 0] + qx * dR[2, 1])
        dqx = 2.0 * (qy * dR[0, 1] + qz * dR[0, 2] + qy * dR[1, 0] - 2.0 * qx * dR[1, 1] - w * dR[1, 2]
                     + qz * dR[2, 0] + w * dR[2, 1] - 2.0 * qx * dR[2, 2])
        dqy = 2.0 * (-2.0 * qy * dR[0, 0] + qx * dR[0, 1] + w * dR[0, 2] + qx * dR[1, 0] + qz * dR[1, 2]
                     - w * dR[2, 0] + qz * dR[2, 1] - 2.0 * qy * dR[2, 2])
        dqz = 2.0 * (-2.0 * qz * dR[0, 0] - w * dR[0, 1] + qx * dR[0, 2] + w * dR[1, 0] - 2.0 * qz * dR[1, 1]
                     + qy * dR[1, 2] + qx * dR[2, 0] + qy * dR[2, 1])
        if small:
            for k in range(4):
                g_quats[g, k] = 0.0
        else:
            dot = w * dw + qx * dqx + qy * dqy + qz * dqz
            g_quats[g, 0] = (dw - w * dot) / qnorm
            g_quats[g, 1] = (dqx - qx * dot) / qnorm
            g_quats[g, 2] = (dqy - qy * dot) / qnorm
            g_quats[g, 3] = (dqz - qz * dot) / qnorm
        # J -> camera point (FOV clamp: a clamped coordinate passes no gradient to x or y)
        tx = z * cxv
        ty = z * cyv
        iz2 = 1.0 / (z * z)
        dz = grads[i, P_Z]
        dz += -fx * iz2 * dJ[0, 0] - fy * iz2 * dJ[1, 1]
        dz += 2.0 * fx * tx * iz2 / z * dJ[0, 2] + 2.0 * fy * ty * iz2 / z * dJ[1, 2]
        dtx = -fx * iz2 * dJ[0, 2]
        dty = -fy * iz2 * dJ[1, 2]
        dx = 0.0
        dy = 0.0
        if clx:
            dz += dtx * cxv
        else:
            dx += dtx
        if cly:
            dz += dty * cyv
        else:
            dy += dty
        # means2d
        dx += du * fx / z
        dy += dv * fy / z
        dz -= du * fx * x * iz2 + dv * fy * y * iz2
        for k in range(3):
            g_means[g, k] = cam[k] * dx + cam[3 + k] * dy + cam[6 + k] * dz
        op = _sigmoid(logits[g])
        g_logits[g] = grads[i, P_OP] * op * (1.0 - op)
