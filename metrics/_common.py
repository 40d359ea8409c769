"""Input checks shared by the metric modules: convert tensors to numpy, validate shapes.

Bad input raises `gsbench.errors.InputError` with a message that names the argument and the
problem, so that an evaluation never produces a number from a malformed array.
"""
from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np

from gsbench.errors import InputError


def to_numpy(x: Any, name: str) -> np.ndarray:
    """numpy view of an array-like or a torch tensor (detached, on the CPU)."""
    try:
        import torch
        if isinstance(x, torch.Tensor):
            return x.detach().cpu().numpy()
    except ImportError:  # pragma: no cover - torch is a core dependency
        pass
    if x is None:
        raise InputError(f"{name}: got None, expected an array")
    return np.asarray(x)


def as_mask(x: Any, name: str) -> np.ndarray:
    """A 2-D boolean mask. Non-bool input counts non-zero as foreground."""
    a = to_numpy(x, name)
    if a.ndim != 2:
        raise InputError(f"{name}: expected a 2-D mask (H, W), got shape {a.shape}")
    if a.size == 0:
        raise InputError(f"{name}: empty array of shape {a.shape}")
    if a.dtype != bool:
        if np.issubdtype(a.dtype, np.floating) and not np.all(np.isfinite(a)):
            raise InputError(f"{name}: mask contains NaN or inf")
        a = a != 0
    return a


def same_shape(a: np.ndarray, b: np.ndarray, na: str, nb: str) -> None:
    if a.shape != b.shape:
        raise InputError(f"{na} has shape {a.shape} but {nb} has shape {b.shape}; they must match")


def finite_float(x: Any, name: str, dtype: Any = np.float64) -> np.ndarray:
    """Float array (float64 unless told) that must be finite everywhere."""
    a = to_numpy(x, name).astype(dtype, copy=False)
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name}: contains NaN or inf")
    return a


def mean_or_none(values: Iterable[float]) -> float | None:
    """Plain mean; None when there are no values (nothing to average is not 0).

    A None or non-finite entry is an error: dropping it silently would bias the mean.
    """
    vals = []
    for v in values:
        if v is None or not math.isfinite(float(v)):
            raise InputError(f"cannot average a missing or non-finite value ({v!r}); "
                             "count it as a skip or give it a defined value first")
        vals.append(float(v))
    if not vals:
        return None
    return math.fsum(vals) / len(vals)


def unit_rows(a: np.ndarray, name: str, *, zero: str = "error", eps: float = 1e-12) -> np.ndarray:
    """L2-normalise the last axis.

    zero="error": an (almost) zero vector raises InputError (text embeddings must not be 0).
    zero="keep": such vectors stay 0, i.e. cosine 0 with everything (a rendered pixel that no
    Gaussian covers has a zero latent; it must not turn into NaN).
    """
    n = np.linalg.norm(a, axis=-1, keepdims=True)
    small = n <= eps
    if np.any(small):
        if zero == "error":
            raise InputError(f"{name}: {int(np.sum(small))} vector(s) have zero norm and cannot be normalised")
        if zero != "keep":
            raise ValueError(f"zero must be 'error' or 'keep', got {zero!r}")
    return a / np.where(small, 1.0, n)


def pixel_norms(features: Any, name: str) -> np.ndarray:
    """L2 norm of every pixel feature of an (H, W, D) map -> (H*W,) float64, summed in float64
    without an (N, D) temporary. A NaN/inf feature is an InputError. Computed once, it serves every
    `pixel_text_cosines` call on the same map (evaluation scores 3D-OVS and LERF from one render)."""
    f = to_numpy(features, name)
    if f.ndim != 3:
        raise InputError(f"{name}: expected (H, W, D), got shape {f.shape}")
    flat = np.ascontiguousarray(f.reshape(-1, f.shape[-1]), dtype=np.float32)
    sq = np.einsum("ij,ij->i", flat, flat, dtype=np.float64)
    if not np.all(np.isfinite(sq)):
        raise InputError(f"{name}: contains NaN or inf")
    return np.sqrt(sq)


def pixel_text_cosines(features: Any, texts: np.ndarray, name: str,
                       norms: np.ndarray | None = None) -> tuple[np.ndarray, tuple[int, int]]:
    """Cosine of every pixel feature (H, W, D) with every text row (K, D) -> ((H*W, K) float64, (H, W)).

    Works on the features in place (float32, no normalised copy: a 985x725x512 map is 1.4 GB).
    A NaN/inf feature is an InputError; a zero feature has cosine 0 with every text.
    norms: `pixel_norms(features)` when the caller has it already (the same values either way).
    """
    f = to_numpy(features, name)
    if f.ndim != 3:
        raise InputError(f"{name}: expected (H, W, D), got shape {f.shape}")
    h, w, d = f.shape
    if texts.ndim != 2 or texts.shape[1] != d:
        raise InputError(f"{name}: feature width {d} does not match the text embeddings {texts.shape}")
    norm = pixel_norms(f, name) if norms is None else np.asarray(norms, np.float64)
    if norm.shape != (h * w,):
        raise InputError(f"{name}: {norm.shape} pixel norms for a {h}x{w} map")
    flat = np.ascontiguousarray(f.reshape(-1, d), dtype=np.float32)
    tu = unit_rows(texts.astype(np.float64), "text embeddings").astype(np.float32)
    dots = (flat @ tu.T).astype(np.float64)
    return np.where(norm[:, None] > 1e-12, dots / np.maximum(norm, 1e-12)[:, None], 0.0), (h, w)
