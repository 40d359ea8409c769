"""Depth priors: gt (simulated estimator), sparse (z-buffered points), noise wiring, errors."""
from __future__ import annotations

import numpy as np
import pytest
from sphere_scene import make_sphere_scene

from gsbench.camera import Camera
from gsbench.errors import InputError
from gsbench.priors import depth as D
from gsbench.priors import prepare_priors
from gsbench.priors import warp as W


def _affine_fit(x, y):
    A = np.c_[x, np.ones_like(x)]
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    return coef, y - A @ coef


def test_gt_prior_is_disparity_up_to_per_view_scale_and_shift():
    scene = make_sphere_scene(4, 96, 72)
    p = prepare_priors(scene, {"depth": {"provider": "gt", "distortion": 0}}, [0, 3, 5], (96, 72), None, True,
                       False, False, seed=0, progress=False)
    assert p.providers["depth"] == "gt-sim-disparity-v3:d0:w518"
    coefs = []
    for v in (0, 3, 5):
        dp = p.depth[v]
        assert dp.kind == "disparity" and dp.values.shape == (72, 96) and dp.values.dtype == np.float32
        z = scene.gt_depth(v)
        assert np.array_equal(dp.valid, z > 0)
        # away from depth edges (blur) the prior is affine in 1/z
        inv = np.where(z > 0, 1.0 / np.maximum(z, 1e-9), 0.0)
        gy, gx = np.gradient(inv)
        flat = dp.valid & (np.hypot(gx, gy) < 0.01)
        from scipy.ndimage import binary_erosion
        flat = binary_erosion(flat, iterations=3)
        assert flat.sum() > 500
        (a, b), res = _affine_fit(inv[flat], dp.values[flat].astype(np.float64))
        assert a > 0
        assert np.abs(res).max() < 0.05 * np.ptp(dp.values[flat])
        coefs.append((a, b))
    # scale/shift differ per view: a single global alignment would not fit
    a = np.array(coefs)
    assert np.ptp(a[:, 0]) / a[:, 0].mean() > 0.05 or np.ptp(a[:, 1]) > 0.05
    # the edges are smeared: at a depth discontinuity the prior is not affine in 1/z
    (a0, b0), _ = _affine_fit(inv[flat], p.depth[5].values[flat].astype(np.float64))
    edge = p.depth[5].valid & (np.hypot(gx, gy) > 0.05)
    assert np.abs(p.depth[5].values[edge] - (a0 * inv[edge] + b0)).mean() > 0.02


def test_gt_prior_is_seeded_per_view_not_per_order():
    scene = make_sphere_scene(3, 48, 36)
    a = prepare_priors(scene, {"depth": {"provider": "gt"}}, [0, 1, 2], (48, 36), None, True, False, False, seed=4,
                       progress=False)
    b = prepare_priors(scene, {"depth": {"provider": "gt"}, "ordering": "random"}, [2, 1, 0], (48, 36), None, True,
                       False, False, seed=4, progress=False)
    c = prepare_priors(scene, {"depth": {"provider": "gt"}}, [0, 1, 2], (48, 36), None, True, False, False, seed=5,
                       progress=False)
    for v in range(3):
        assert np.array_equal(a.depth[v].values, b.depth[v].values)
    assert not np.array_equal(a.depth[0].values, c.depth[0].values)


def test_depth_at_image_size():
    scene = make_sphere_scene(2, 64, 48)
    p = prepare_priors(scene, {"depth": {"provider": "gt"}}, [0], (32, 24), None, True, False, False, progress=False)
    assert p.depth[0].values.shape == (24, 32)


def test_sparse_prior_hand_computed_zbuffer():
    K = np.array([[10.0, 0, 5.0], [0, 10.0, 5.0], [0, 0, 1]])
    cam = Camera(K, np.eye(4), 10, 10)
    # two points on the same ray through pixel (7, 2) centre (7.5, 2.5): x/z = 0.25, y/z = -0.25
    pts = np.array([[0.5, -0.5, 2.0], [1.0, -1.0, 4.0],   # same pixel, z = 2 wins
                    [0.0, 0.0, 3.0],                      # pixel (5, 5)
                    [0.0, 0.0, -1.0],                     # behind the camera
                    [50.0, 0.0, 1.0]])                    # outside the image
    vals, valid = D.sparse_depth_prior(pts, cam)
    assert valid.sum() == 2
    assert valid[2, 7] and vals[2, 7] == pytest.approx(2.0)
    assert valid[5, 5] and vals[5, 5] == pytest.approx(3.0)
    assert vals[~valid].max() == 0.0


def test_sparse_prior_matches_gt_depth_where_visible():
    scene = make_sphere_scene(3, 96, 72)
    p = prepare_priors(scene, {"depth": {"provider": "sparse"}}, [0, 1], (96, 72), None, True, False, False,
                       progress=False)
    dp = p.depth[1]
    assert dp.kind == "depth" and p.providers["depth"].startswith("sparse")
    z = scene.gt_depth(1)
    m = dp.valid & (z > 0)
    assert m.sum() > 50
    rel = np.abs(dp.values[m] - z[m]) / z[m]
    # surface points land on the surface they belong to (pixel quantisation aside)
    assert np.median(rel) < 0.02


def test_missing_parts_raise_input_error():
    scene = make_sphere_scene(2, 16, 12)
    scene.depth_loader = None
    with pytest.raises(InputError, match="GT depth"):
        prepare_priors(scene, {"depth": {"provider": "gt"}}, [0], (16, 12), None, True, False, False, progress=False)
    scene.points = None
    with pytest.raises(InputError, match="sparse points"):
        prepare_priors(scene, {"depth": {"provider": "sparse"}}, [0], (16, 12), None, True, False, False,
                       progress=False)
    with pytest.raises(InputError, match="priors.depth.provider"):
        prepare_priors(scene, {"depth": {"provider": "lidar"}}, [0], (16, 12), None, True, False, False, progress=False)


def test_provider_none_skips():
    scene = make_sphere_scene(2, 16, 12)
    p = prepare_priors(scene, {"depth": {"provider": "none"}}, [0], (16, 12), None, True, False, False, progress=False)
    assert p.depth is None and p.providers["depth"] is None and "depth" in p.skipped


def test_depth_anything_missing_weights_one_line_error(tmp_path):
    scene = make_sphere_scene(2, 16, 12)
    missing = tmp_path / "weights" / "depth-anything-small"
    with pytest.raises(InputError) as e:
        prepare_priors(scene, {"depth": {"provider": "depth-anything", "model_path": str(missing)}}, [0], (16, 12),
                       tmp_path / "cache", True, False, False, progress=False)
    msg = str(e.value)
    assert "\n" not in msg
    assert "priors.depth.model_path" in msg and str(missing) in msg and "priors.depth.provider=depth-anything" in msg
    with pytest.raises(InputError, match="priors.depth.model_path: not set"):
        prepare_priors(scene, {"depth": {"provider": "depth-anything"}}, [0], (16, 12), None, True, False, False,
                       progress=False)


def test_noise_goes_through_datasets_noise_on_the_prior_only(tmp_path, monkeypatch):
    calls = []

    def fake_apply_noise(depth, valid, kind, severity, seed):
        calls.append((depth.copy(), valid.copy(), kind, severity, seed))
        return depth + 1.0, valid

    import gsbench.priors.depth as PD
    monkeypatch.setattr(PD, "apply_noise", fake_apply_noise)   # where the depth prior looks it up
    scene = make_sphere_scene(2, 32, 24)
    cfg = {"depth": {"provider": "gt", "noise": {"type": "gaussian", "severity": 3}}}
    clean = prepare_priors(scene, {"depth": {"provider": "gt"}}, [0, 1], (32, 24), tmp_path, True, False, False,
                           progress=False)
    noisy = prepare_priors(scene, cfg, [0, 1], (32, 24), tmp_path, True, False, False, progress=False)
    assert len(calls) == 2 and {c[2] for c in calls} == {"gaussian"} and {c[3] for c in calls} == {3}
    assert calls[0][4] != calls[1][4]                       # per-view seeds
    for v in (0, 1):
        assert np.allclose(noisy.depth[v].values, clean.depth[v].values + 1.0)
    assert noisy.providers["depth"] == clean.providers["depth"] + "+noise:gaussian:s3"
    # the clean prior came from the cache: noise is applied after it
    assert noisy.cache["depth"]["hit"] is True


def test_real_noise_module_changes_depth():
    noise = pytest.importorskip("gsbench.datasets.noise")
    scene = make_sphere_scene(2, 32, 24)
    clean = prepare_priors(scene, {"depth": {"provider": "gt"}}, [0], (32, 24), None, True, False, False,
                           progress=False)
    noisy = prepare_priors(scene, {"depth": {"provider": "gt", "noise": {"type": "salt_pepper", "severity": 5}}},
                           [0], (32, 24), None, True, False, False, progress=False)
    changed = clean.depth[0].values != noisy.depth[0].values
    assert changed.any() and not changed[~clean.depth[0].valid].any()
    assert hasattr(noise, "apply_noise")


def test_zbuffer_splat_keeps_nearest():
    cam = Camera(np.array([[4.0, 0, 2], [0, 4.0, 2], [0, 0, 1]]), np.eye(4), 4, 4)
    pts = np.array([[0.0, 0.0, 5.0], [0.0, 0.0, 1.0], [0.0, 0.0, 3.0]])   # all on the axis, pixel (2, 2)
    vals, zmap = W.zbuffer_splat(pts, np.array([7, 8, 9], dtype=np.int32), cam, fill=np.int32(-1))
    assert vals[2, 2] == 8 and zmap[2, 2] == 1.0 and (vals >= 0).sum() == 1


def test_distortion_severity_adds_what_scale_shift_cannot_remove(tmp_path):
    from gsbench.priors.depth import gt_disparity_prior
    z = make_sphere_scene(1, 96, 72).gt_depth(0)
    ok = z > 0
    inv = np.where(ok, 1.0 / np.maximum(z, 1e-9), 0.0)
    res = []
    for sev in (0, 1, 3):
        vals, valid = gt_disparity_prior(z, np.random.default_rng(4), sev)
        assert np.array_equal(valid, ok) and np.isfinite(vals).all()
        (_, _), r = _affine_fit(inv[ok], vals[ok].astype(np.float64))
        res.append(float(np.sqrt(np.mean(r ** 2)) / np.ptp(vals[ok])))
    assert res[0] < res[1] < res[2]
    # the same rng gives the same scale and shift whatever the severity: only the distortion moves
    a, _ = gt_disparity_prior(z, np.random.default_rng(4), 0)
    b, _ = gt_disparity_prior(z, np.random.default_rng(4), 0)
    assert np.array_equal(a, b)
    # extreme severity stays finite (exp is clipped)
    big, _ = gt_disparity_prior(z, np.random.default_rng(4), 1e6)
    assert np.isfinite(big).all()
    scene = make_sphere_scene(2, 48, 36)
    keys = {prepare_priors(scene, {"depth": {"provider": "gt", "distortion": d}}, [0, 1], (48, 36), tmp_path,
                           True, False, False, progress=False).cache["depth"]["key"] for d in (0, 1, 2)}
    assert len(keys) == 3
    with pytest.raises(InputError, match="priors.depth.distortion"):
        prepare_priors(scene, {"depth": {"provider": "gt", "distortion": -1}}, [0], (48, 36), None, True, False,
                       False, progress=False)
