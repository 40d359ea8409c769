"""Depth-noise injection for the depth_noise study: seeded perturbations of a depth map at named
severity levels (0 = identity, 1..5 increasing).

Scale-free: every level is relative to the median valid depth `m`, so one table serves metric GT
depth and relative priors alike. Per kind and level 1..5:
  gaussian     additive N(0, s * m), s = 0.01, 0.02, 0.05, 0.10, 0.20
  poisson      shot noise: d' = m / N * Poisson(N * d / m), N = 1000, 300, 100, 30, 10 counts at depth m
  motion_blur  a line kernel of 3, 5, 9, 15, 21 px at an angle drawn from the seed, normalised over valid pixels only
               (invalid pixels never bleed in)
  salt_pepper  a fraction p = 0.01, 0.02, 0.05, 0.10, 0.20 of valid pixels set to the smallest (pepper)
               or largest (salt) valid depth, half each
NaN-safe: only pixels that are valid and finite are read or changed; the returned mask is
`valid & isfinite(depth)` (so the valid mask is kept), other pixels keep their input values.
Outputs are clipped to >= 1e-3 * m so that depth stays positive where it is valid.
"""
from __future__ import annotations

import cv2
import numpy as np

from gsbench.config_keys import NOISE_SEVERITIES, NOISE_TYPES
from gsbench.errors import InputError

NOISE_KINDS = tuple(k for k in NOISE_TYPES if k is not None)   # config_keys declares them (None: no noise)
SEVERITIES = NOISE_SEVERITIES
LEVELS = {
    "gaussian": (0.0, 0.01, 0.02, 0.05, 0.10, 0.20),
    "poisson": (np.inf, 1000.0, 300.0, 100.0, 30.0, 10.0),
    "motion_blur": (1, 3, 5, 9, 15, 21),
    "salt_pepper": (0.0, 0.01, 0.02, 0.05, 0.10, 0.20),
}


def _line_kernel(length: int, angle: float) -> np.ndarray:
    """A `length`-tap line through the kernel centre: one tap per pixel along the dominant axis."""
    k = np.zeros((length, length), np.float32)
    c = (length - 1) // 2
    dx, dy = np.cos(angle), np.sin(angle)
    for t in range(-c, c + 1):
        if abs(dx) >= abs(dy):
            k[c + int(round(t * dy / dx)), c + t] = 1.0
        else:
            k[c + t, c + int(round(t * dx / dy))] = 1.0
    return k / k.sum()


def apply_noise(
    depth: np.ndarray, valid: np.ndarray, kind: str, severity: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Perturbed depth (same dtype and shape) and its valid mask; severity 0 returns copies."""
    if kind not in NOISE_KINDS:
        raise InputError(f"unknown noise kind {kind!r}; choose one of {', '.join(NOISE_KINDS)}")
    if int(severity) != severity or severity not in SEVERITIES:
        raise InputError(f"noise severity must be one of {SEVERITIES}, got {severity!r}")
    depth = np.asarray(depth)
    valid = np.asarray(valid, bool)
    if depth.shape != valid.shape or depth.ndim != 2:
        raise ValueError(f"depth {depth.shape} and valid {valid.shape} must be the same 2-D shape")
    if severity == 0:
        return depth.copy(), valid.copy()
    v = valid & np.isfinite(depth)
    out = depth.astype(np.float64, copy=True)
    if not v.any():
        return out.astype(depth.dtype), v
    d = out[v]
    m = float(np.median(np.abs(d)))
    if not m > 0:
        m = float(np.max(np.abs(d))) or 1.0
    rng = np.random.default_rng([int(seed), NOISE_KINDS.index(kind), int(severity)])
    level = LEVELS[kind][severity]
    if kind == "gaussian":
        d = d + rng.normal(0.0, level * m, size=d.shape)
    elif kind == "poisson":
        lam = np.clip(level * np.maximum(d, 0.0) / m, 0.0, 1e12)
        d = rng.poisson(lam).astype(np.float64) * (m / level)
    elif kind == "motion_blur":
        # the angle depends on the seed only, so severities of one seed blur along the same line
        angle = float(np.random.default_rng([int(seed), NOISE_KINDS.index(kind)]).uniform(0, np.pi))
        k = _line_kernel(int(level), angle)
        num = cv2.filter2D(np.where(v, out, 0.0), cv2.CV_64F, k, borderType=cv2.BORDER_CONSTANT)
        den = cv2.filter2D(v.astype(np.float64), cv2.CV_64F, k, borderType=cv2.BORDER_CONSTANT)
        d = num[v] / np.maximum(den[v], 1e-12)  # den > 0 at valid pixels: the kernel centre is in it
    else:  # salt_pepper
        lo, hi = float(d.min()), float(d.max())
        hit = rng.random(d.shape) < level
        salt = rng.random(d.shape) < 0.5
        d = np.where(hit, np.where(salt, hi, lo), d)
    out[v] = np.maximum(d, 1e-3 * m)
    return out.astype(depth.dtype), v
