"""Depth-noise injection: identity at severity 0, seeded, NaN-safe, mask-preserving, increasing."""
from __future__ import annotations

import numpy as np
import pytest

from gsbench.datasets.noise import NOISE_KINDS, SEVERITIES, apply_noise


def _depth(seed: int = 0):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:48, 0:64]
    d = (2.0 + 0.02 * xx + 0.01 * yy + 0.05 * rng.random((48, 64))).astype(np.float32)
    valid = np.ones_like(d, bool)
    valid[:6] = False          # an invalid band
    valid[20:24, 30:40] = False  # an invalid hole
    d[~valid] = np.nan
    d[0, 0] = np.inf
    return d, valid


def test_kinds_and_levels():
    assert set(NOISE_KINDS) == {"gaussian", "poisson", "motion_blur", "salt_pepper"}
    assert tuple(SEVERITIES) == (0, 1, 2, 3, 4, 5)


@pytest.mark.parametrize("kind", NOISE_KINDS)
def test_severity_zero_is_identity(kind):
    d, v = _depth()
    out, ov = apply_noise(d, v, kind, 0, seed=3)
    assert np.array_equal(out, d, equal_nan=True) and np.array_equal(ov, v)
    assert out is not d


@pytest.mark.parametrize("kind", NOISE_KINDS)
@pytest.mark.parametrize("severity", [1, 3, 5])
def test_seeded_finite_mask_preserved(kind, severity):
    d, v = _depth()
    a, va = apply_noise(d, v, kind, severity, seed=11)
    b, vb = apply_noise(d, v, kind, severity, seed=11)
    c, _ = apply_noise(d, v, kind, severity, seed=12)
    assert np.array_equal(a, b, equal_nan=True) and np.array_equal(va, vb)
    assert np.array_equal(va, v & np.isfinite(d))
    assert np.all(np.isfinite(a[va])) and np.all(a[va] > 0)
    assert np.array_equal(a[~va], d[~va], equal_nan=True)  # invalid pixels untouched
    assert a.dtype == d.dtype and a.shape == d.shape
    assert not np.array_equal(a[va], d[va])
    if kind != "motion_blur":  # the blur angle is the only random part and may coincide
        assert not np.array_equal(a, c, equal_nan=True)


@pytest.mark.parametrize("kind", NOISE_KINDS)
def test_error_grows_with_severity(kind):
    d, v = _depth()
    ok = v & np.isfinite(d)
    errs = [np.mean(np.abs(apply_noise(d, v, kind, s, seed=5)[0][ok] - d[ok])) for s in range(1, 6)]
    assert all(b > a for a, b in zip(errs, errs[1:])), errs


def test_gaussian_std_matches_level():
    d = np.full((200, 200), 4.0, np.float32)
    v = np.ones_like(d, bool)
    out, _ = apply_noise(d, v, "gaussian", 3, seed=0)  # level 3: sigma = 0.05 x median = 0.2
    assert np.std(out - d) == pytest.approx(0.2, rel=0.03)


def test_motion_blur_does_not_bleed_invalid_and_keeps_constants():
    d = np.full((40, 40), 3.0, np.float32)
    v = np.ones_like(d, bool)
    v[10:30, 10:30] = False
    d[~v] = 100.0  # garbage behind the invalid mask must not leak in
    out, ov = apply_noise(d, v, "motion_blur", 5, seed=2)
    np.testing.assert_allclose(out[ov], 3.0, rtol=1e-6)


def test_salt_pepper_fraction():
    d, v = _depth(1)
    ok = v & np.isfinite(d)
    out, _ = apply_noise(d, v, "salt_pepper", 4, seed=9)  # level 4: 10 % of valid pixels
    changed = np.mean(out[ok] != d[ok])
    assert 0.08 < changed < 0.12
    assert set(np.unique(out[ok][out[ok] != d[ok]])) <= {d[ok].min(), d[ok].max()}


def test_bad_arguments():
    d, v = _depth()
    with pytest.raises(ValueError, match="unknown noise kind"):
        apply_noise(d, v, "speckle", 1, 0)
    with pytest.raises(ValueError, match="severity"):
        apply_noise(d, v, "gaussian", 6, 0)
    with pytest.raises(ValueError, match="same 2-D shape"):
        apply_noise(d, v[:-1], "gaussian", 1, 0)
