"""Losses of the trainer / GaussianDS: hand-checked values and independent references."""
import math

import numpy as np
import pytest
import torch

from gsbench.train.losses import (depth_edges, depth_loss, ds_loss, l1, reconstruction_loss, sem_loss,  # isort: skip
                                    solve_scale_shift, ssim, tv_loss)


# ---------------------------------------------------------------------------- scale / shift
@pytest.mark.parametrize("seed", range(5))
def test_scale_shift_matches_numpy_lstsq(seed):
    rng = np.random.default_rng(seed)
    n = 500
    x = rng.normal(3.0, 2.0, n)
    y = -1.7 * x + 0.4 + rng.normal(0, 0.5, n)
    valid = rng.random(n) > 0.3
    A = np.stack([x[valid], np.ones(valid.sum())], 1)
    (s_ref, t_ref), *_ = np.linalg.lstsq(A, y[valid], rcond=None)
    st = solve_scale_shift(x, y, valid)
    assert st.ok
    assert st.s == pytest.approx(s_ref, rel=1e-9, abs=1e-12)
    assert st.t == pytest.approx(t_ref, rel=1e-9, abs=1e-12)


def test_scale_shift_constant_prior_skipped():
    st = solve_scale_shift(np.full(100, 7.0), np.arange(100.0))
    assert not st.ok and math.isfinite(st.s) and math.isfinite(st.t)
    st0 = solve_scale_shift(np.zeros(100), np.arange(100.0))
    assert not st0.ok


def test_scale_shift_all_invalid_and_too_few():
    x = np.arange(100.0)
    assert not solve_scale_shift(x, x, np.zeros(100, bool)).ok
    few = np.zeros(100, bool)
    few[:9] = True
    assert not solve_scale_shift(x, 2 * x, few, min_valid=10).ok
    few[:10] = True
    st = solve_scale_shift(x, 2 * x + 1, few, min_valid=10)
    assert st.ok and st.s == pytest.approx(2.0) and st.t == pytest.approx(1.0)
    # NaN / inf are treated as invalid, not propagated
    xn = x.copy()
    xn[5] = np.nan
    xn[6] = np.inf
    st = solve_scale_shift(xn, 3 * x - 2)
    assert st.ok and st.s == pytest.approx(3.0) and st.t == pytest.approx(-2.0)


@pytest.mark.parametrize("mag", [1e-150, 1e150, 1e300])
def test_scale_shift_huge_and_tiny_magnitudes_stay_finite(mag):
    rng = np.random.default_rng(1)
    x = rng.random(200)
    y = 0.5 * x + 0.25 + rng.normal(0, 0.01, 200)
    (s_ref, t_ref), *_ = np.linalg.lstsq(np.stack([x, np.ones_like(x)], 1), y, rcond=None)
    st = solve_scale_shift(x * mag, y * mag)          # s is scale-free, t scales with the target
    assert st.ok and math.isfinite(st.s) and math.isfinite(st.t)
    assert st.s == pytest.approx(s_ref, rel=1e-9)
    assert st.t == pytest.approx(t_ref * mag, rel=1e-9)
    st2 = solve_scale_shift(x * mag, y)               # prior huge, target O(1): s = s_ref / mag
    assert st2.ok and st2.s == pytest.approx(s_ref / mag, rel=1e-9) and st2.t == pytest.approx(t_ref, rel=1e-9)


# ---------------------------------------------------------------------------- depth formulations
def _ramp(h=12, w=16):
    yy, xx = np.mgrid[0:h, 0:w]
    return (1.0 + 0.1 * xx + 0.05 * yy).astype(np.float32)


def test_depth_scale_shift_exact_alignment_is_zero_and_float64():
    D = torch.tensor(_ramp())
    prior = (D.numpy() - 3.0) / 2.0                       # D = 2 * prior + 3
    t = depth_loss("scale_shift", D, prior, np.ones(D.shape, bool), "depth")
    assert bool(t.ok) and float(t.loss) == pytest.approx(0.0, abs=1e-5)
    assert float(t.s) == pytest.approx(2.0, rel=1e-5) and float(t.t) == pytest.approx(3.0, rel=1e-5)


def test_depth_disparity_aligned_in_inverse_depth():
    D = torch.tensor(_ramp())
    prior = 0.5 / D.numpy() + 0.1                           # disparity: 1/D = 2 * prior - 0.2
    t = depth_loss("scale_shift", D, prior, np.ones(D.shape, bool), "disparity")
    assert float(t.loss) == pytest.approx(0.0, abs=1e-5)
    assert float(t.s) == pytest.approx(2.0, rel=1e-4) and float(t.t) == pytest.approx(-0.2, abs=1e-4)
    # empty rendered pixels (D = 0) are guarded: not used, no inf/NaN in the loss or its gradient
    D2 = D.clone()
    D2[:2] = 0.0
    D2.requires_grad_(True)
    t2 = depth_loss("scale_shift", D2, prior, np.ones(D.shape, bool), "disparity")
    t2.loss.backward()
    assert float(t2.loss.detach()) == pytest.approx(0.0, abs=1e-5)
    assert torch.isfinite(D2.grad).all()


def test_depth_raw_minmax_pearson_hand_values():
    D = torch.tensor([[1.0, 2.0], [3.0, 4.0]])
    valid = np.ones((2, 2), bool)
    prior = np.array([[1.5, 2.5], [3.5, 4.5]], np.float32)
    raw = depth_loss("raw_l1", D, prior, valid, "depth", min_valid=2)
    assert float(raw.loss) == pytest.approx(0.5)
    rev = np.array([[4.0, 3.0], [2.0, 1.0]], np.float32)   # minmax: render -> 0,1/3,2/3,1, prior -> 1,2/3,1/3,0
    mm = depth_loss("minmax", D, rev, valid, "depth", min_valid=2)
    assert float(mm.loss) == pytest.approx((1 + 1 / 3 + 1 / 3 + 1) / 4)
    pe = depth_loss("pearson", D, rev, valid, "depth", min_valid=2)
    assert float(pe.loss) == pytest.approx(2.0, abs=1e-6)    # 1 - (-1)
    pe2 = depth_loss("pearson", D, 5 * D.numpy() + 1, valid, "depth", min_valid=2)
    assert float(pe2.loss) == pytest.approx(0.0, abs=1e-6)
    assert depth_loss("none", D, prior, valid, "depth").loss is None


def test_depth_skips_few_valid_and_constant():
    D = torch.tensor(_ramp())
    v = np.zeros(D.shape, bool)
    v[0, :9] = True
    for form in ("raw_l1", "minmax", "scale_shift", "pearson"):
        few = depth_loss(form, D, D.numpy(), v, "depth", min_valid=10)
        assert not bool(few.ok) and float(few.loss) == 0.0
        const = depth_loss(form if form != "raw_l1" else "minmax", D, np.full(D.shape, 2.0, np.float32),
                           np.ones(D.shape, bool), "depth")
        assert not bool(const.ok) and float(const.loss) == 0.0


# ---------------------------------------------------------------------------- TV / semantics
def test_tv_on_linear_ramp_is_exact():
    a, b, eps = 0.3, -0.4, 1e-6
    yy, xx = torch.meshgrid(torch.arange(10.0), torch.arange(13.0), indexing="ij")
    D = a * xx + b * yy
    assert float(tv_loss(D, eps)) == pytest.approx(math.sqrt(a * a + b * b + eps), rel=1e-6)
    assert float(tv_loss(torch.zeros(5, 5), 1e-6)) == pytest.approx(1e-3, rel=1e-6)


def test_sem_and_ds_hand_values():
    s_hat = torch.zeros(2, 2, 3)
    target = torch.ones(2, 2, 3)
    target[1, 1] = 100.0                       # no target there: must be ignored
    has = torch.tensor([[True, True], [True, False]])
    assert float(sem_loss(s_hat, target, has)) == pytest.approx(1.0)
    edges = torch.tensor([[1.0, 0.0], [0.0, 1.0]])
    # |E * diff| over the 3 pixels with a target: (1 + 0 + 0) * 1 per channel -> 1/3
    assert float(ds_loss(s_hat, target, has, edges)) == pytest.approx(1.0 / 3.0)
    # averaged over the edge pixels with a target: only (0, 0) -> 1 (the (1, 1) edge has no target)
    assert float(ds_loss(s_hat, target, has, edges, "edges")) == pytest.approx(1.0)
    assert float(ds_loss(s_hat, target, has, torch.zeros(2, 2), "edges")) == 0.0     # no edge: 0, not NaN
    with pytest.raises(ValueError, match="average"):
        ds_loss(s_hat, target, has, edges, "mean")
    assert float(sem_loss(s_hat, target, torch.zeros(2, 2, dtype=torch.bool))) == 0.0


def test_l1_and_reconstruction_hand_values():
    a = torch.zeros(8, 8, 3)
    b = torch.full((8, 8, 3), 0.5)
    assert float(l1(a, b)) == pytest.approx(0.5)
    assert float(reconstruction_loss(a, b, 0.0)) == pytest.approx(0.5)
    img = torch.rand(16, 16, 3, generator=torch.Generator().manual_seed(0))
    assert float(reconstruction_loss(img, img, 0.2)) == pytest.approx(0.0, abs=1e-6)


def test_ssim_constant_images_interior_formula():
    # away from the zero-padded border two constant images give (2 c1 c2 + C1) / (c1^2 + c2^2 + C1)
    from gsbench.train.losses import ssim_map
    c1, c2 = 0.8, 0.4
    a = torch.full((40, 40, 1), c1, dtype=torch.float64)   # float64: E[x^2] - mu^2 cancels exactly enough
    b = torch.full((40, 40, 1), c2, dtype=torch.float64)
    C1 = 0.01 ** 2
    expect = (2 * c1 * c2 + C1) / (c1 * c1 + c2 * c2 + C1)
    m = ssim_map(a, b)[0, 0]
    np.testing.assert_allclose(m[5:-5, 5:-5].numpy(), expect, rtol=1e-5)
    assert float(ssim(a, b)) == pytest.approx(float(m.mean()), rel=1e-6)
    assert float(ssim(a, a)) == pytest.approx(1.0, abs=1e-6)


def test_ssim_matches_skimage_on_interior():
    skm = pytest.importorskip("skimage.metrics")
    rng = np.random.default_rng(0)
    x = rng.random((48, 48)).astype(np.float64)
    y = np.clip(x + rng.normal(0, 0.1, x.shape), 0, 1)
    _, full = skm.structural_similarity(x, y, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                                        data_range=1.0, full=True)
    # our SSIM with zero padding equals skimage's on pixels at least 5 from the border
    from gsbench.train import losses as L
    xt, yt = torch.tensor(x)[..., None], torch.tensor(y)[..., None]
    a, b = xt.permute(2, 0, 1)[None], yt.permute(2, 0, 1)[None]
    w = L._gaussian_window(11, 1.5, 1, a.device, a.dtype)
    import torch.nn.functional as F
    mu1, mu2 = F.conv2d(a, w, padding=5), F.conv2d(b, w, padding=5)
    s1 = F.conv2d(a * a, w, padding=5) - mu1 ** 2
    s2 = F.conv2d(b * b, w, padding=5) - mu2 ** 2
    s12 = F.conv2d(a * b, w, padding=5) - mu1 * mu2
    m = ((2 * mu1 * mu2 + L.SSIM_C1) * (2 * s12 + L.SSIM_C2)
         / ((mu1 ** 2 + mu2 ** 2 + L.SSIM_C1) * (s1 + s2 + L.SSIM_C2)))[0, 0]
    np.testing.assert_allclose(m.numpy()[5:-5, 5:-5], full[5:-5, 5:-5], atol=1e-6)
    # and the scalar loss is the mean of that map
    assert float(ssim(xt, yt)) == pytest.approx(float(m.mean()), abs=1e-9)


# ---------------------------------------------------------------------------- depth edges
def test_depth_edges_step_and_affine_invariance():
    v = np.ones((20, 30), np.float32)
    v[:, 15:] = 5.0
    valid = np.ones(v.shape, bool)
    e = depth_edges(v, valid, 50, 150, dilate=0)
    cols = np.unique(np.nonzero(e)[1])
    assert set(cols.tolist()) <= {14, 15} and len(cols) >= 1
    assert not e[:, :13].any() and not e[:, 17:].any()
    e2 = depth_edges(3.7 * v + 11.0, valid, 50, 150, dilate=0)
    np.testing.assert_array_equal(e, e2)
    ed = depth_edges(v, valid, 50, 150, dilate=1)
    assert ed.sum() > e.sum() and (ed | e).sum() == ed.sum()
    assert not depth_edges(np.full((10, 10), 3.0), np.ones((10, 10), bool)).any()


def _soft_step(width: int, height: int, at: float, spread: float) -> np.ndarray:
    """A disparity that climbs from 1 to 2 over `spread` pixels around column `at` (a step upsampled
    from a coarser map is such a ramp)."""
    x = np.arange(width, dtype=np.float64)
    return np.tile(1.0 + np.clip((x - at) / spread + 0.5, 0.0, 1.0), (height, 1))


def test_depth_edges_at_a_working_size_find_a_soft_step_the_full_size_misses():
    """A step spread over 16 pixels climbs 255 / 16 levels per pixel: Sobel gives 8 x 16 = 128 < 150, so
    Canny at full size finds nothing. At a quarter of the size the ramp is 4 pixels (Sobel 512) and the
    edge is found, back at full size within a few working pixels of the step, and nowhere else."""
    v, valid = _soft_step(1000, 400, 600.0, 16.0), np.ones((400, 1000), bool)
    assert not depth_edges(v, valid, 50, 150, dilate=1).any()
    e = depth_edges(v, valid, 50, 150, dilate=1, size=100)           # Canny on 250 x 100
    cols = np.unique(np.nonzero(e)[1])
    assert e.shape == v.shape and len(cols) > 0
    # within +- (2 for the ramp + 2 for the dilation) working pixels of the step
    assert cols.min() >= 600 - 4 * 4 and cols.max() <= 600 + 4 * 4
    # the size is a short side: a prior no larger than it is left as it is
    np.testing.assert_array_equal(depth_edges(v, valid, 50, 150, 1, size=400), depth_edges(v, valid, 50, 150, 1))


def test_depth_edges_share_follows_the_working_size_not_the_view_size():
    """The same sharp step at 1000 x 400 with size 100 and at 250 x 100 without: the same share of pixels
    (Canny's one-pixel line, dilated, is a share of the working width either way)."""
    big = depth_edges(_soft_step(1000, 400, 600.0, 1e-3), np.ones((400, 1000), bool), 50, 150, 1, size=100)
    small = depth_edges(_soft_step(250, 100, 150.0, 1e-3), np.ones((100, 250), bool), 50, 150, 1)
    assert small.mean() > 0 and big.mean() == pytest.approx(small.mean(), rel=0.05)
    assert depth_edges(_soft_step(1000, 400, 600.0, 1e-3), np.ones((400, 1000), bool), 50, 150, 1).mean() \
        < big.mean() / 3                                             # at full size it is a quarter of that


def test_depth_edges_at_a_working_size_keep_out_of_invalid_pixels():
    v = _soft_step(1000, 400, 600.0, 1e-3)
    valid = np.ones(v.shape, bool)
    valid[:, 800:] = False                 # the invalid border is no edge, and invalid pixels get none
    v[~valid] = np.nan
    e = depth_edges(v, valid, 50, 150, 1, size=100)
    assert e.any() and not e[:, 780:].any()


def test_expected_depth_is_the_depth_of_the_covered_part():
    from gsbench.train.losses import expected_depth
    D = torch.tensor([[2.0, 1.0, 0.0, 3.0]])
    alpha = torch.tensor([[1.0, 0.5, 0.0, 1e-4]])
    # 2 / 1 = 2, 1 / 0.5 = 2, uncovered pixels are 0 (the depth loss does not use them)
    assert torch.equal(expected_depth(D, alpha), torch.tensor([[2.0, 2.0, 0.0, 0.0]]))


def test_depth_loss_does_not_read_coverage_as_depth():
    """Two surfaces at z = 1 and z = 2 with an exact disparity prior; half the far pixels are only
    half covered (composited D = 0.5 * 2 = 1). On D the loss sees them as near surface; on D / alpha
    it is zero."""
    from gsbench.train.losses import expected_depth
    z = torch.tensor([[1.0, 1.0, 2.0, 2.0], [1.0, 1.0, 2.0, 2.0]])
    alpha = torch.tensor([[1.0, 1.0, 1.0, 0.5], [1.0, 1.0, 1.0, 0.5]])
    D = z * alpha
    prior = 3.0 / z + 0.25          # disparity up to scale and shift
    valid = torch.ones_like(z, dtype=torch.bool)
    on_d = depth_loss("scale_shift", D, prior, valid, "disparity", min_valid=2)
    on_e = depth_loss("scale_shift", expected_depth(D, alpha), prior, valid, "disparity", min_valid=2)
    assert float(on_e.loss) == pytest.approx(0.0, abs=1e-6)
    assert float(on_d.loss) > 0.1


def test_edge_coverage_hand_computed():
    from gsbench.train.losses import edge_coverage
    a = np.zeros((10, 10), bool)
    a[0, :3] = True                      # 3 % of the pixels
    b = np.zeros((10, 10), bool)
    b[5, 5] = True                       # 1 %
    c = np.zeros((20, 50), bool)         # none
    share, empty = edge_coverage({0: a, 1: b, 2: c}, floor=0.02)
    assert share == pytest.approx(0.04 / 3) and empty == 2
    assert edge_coverage({0: a, 1: b, 2: c}) == (pytest.approx(0.04 / 3), 1)
    assert edge_coverage({}) == (0.0, 0)
