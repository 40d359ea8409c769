"""The CPU SSIM loss (gsbench/train/ssim_cpu.py) against the PyTorch `ssim_map` and finite differences."""
from __future__ import annotations

import numba
import numpy as np
import pytest
import torch

from gsbench.metrics.ssim_definition import SSIM_C1, SSIM_C2, SSIM_WINDOW
from gsbench.train import losses as L
from gsbench.train import ssim_cpu as SC
from gsbench.train.ssim_cpu import ssim_mean_cpu


def _window(dtype=torch.float64):
    g = L._gaussian_1d(11, 1.5, "cpu", torch.float64).numpy()
    return g.astype("float32" if dtype == torch.float32 else "float64")


def _value_and_grads(fn, a, b):
    a = a.clone().requires_grad_(True)
    b = b.clone().requires_grad_(True)
    v = fn(a, b)
    v.backward()
    return float(v.detach()), a.grad, b.grad


def _pair(h, w, c, seed, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    a = torch.rand(h, w, c, generator=g, dtype=torch.float64)
    b = (a + 0.1 * torch.randn(h, w, c, generator=g, dtype=torch.float64)).clamp(0, 1)
    return a.to(dtype), b.to(dtype)


@pytest.mark.parametrize("shape", [(48, 64, 3), (7, 5, 2), (1, 1, 3), (3, 40, 1), (40, 3, 1)])
def test_float64_equals_the_pytorch_ssim_map_value_and_both_gradients(shape):
    a, b = _pair(*shape, seed=sum(shape))
    ref = _value_and_grads(lambda x, y: L.ssim_map(x, y).mean(), a, b)
    got = _value_and_grads(lambda x, y: ssim_mean_cpu(x, y, _window(), L.SSIM_C1, L.SSIM_C2), a, b)
    assert got[0] == pytest.approx(ref[0], abs=1e-13)
    for g_ref, g_got in zip(ref[1:], got[1:]):
        torch.testing.assert_close(g_got, g_ref, rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("shape", [(24, 31, 3), (11, 11, 1), (12, 6, 2)])
def test_agrees_with_the_pytorch_ssim_map_where_only_the_border_differs(shape):
    """Images equal inside and different only in the 5-px frame the zero padding reaches: the value
    and both gradients come from the border pixels, and the two training forms agree there."""
    a, b = _pair(*shape, seed=7)
    r = SSIM_WINDOW // 2
    b[r:-r, r:-r] = a[r:-r, r:-r]
    ref = _value_and_grads(lambda x, y: L.ssim_map(x, y).mean(), a, b)
    got = _value_and_grads(lambda x, y: ssim_mean_cpu(x, y, _window(), SSIM_C1, SSIM_C2), a, b)
    assert ref[0] < 1.0 - 1e-3                     # the frame does differ
    assert got[0] == pytest.approx(ref[0], abs=1e-13)
    for g_ref, g_got in zip(ref[1:], got[1:]):
        torch.testing.assert_close(g_got, g_ref, rtol=1e-10, atol=1e-14)


def test_the_training_forms_take_the_one_ssim_definition():
    import inspect

    from gsbench.metrics import ssim_definition as D
    for fn in (L.ssim, L.ssim_map):
        params = inspect.signature(fn).parameters
        assert params["window_size"].default == D.SSIM_WINDOW and params["sigma"].default == D.SSIM_SIGMA
    assert (L.SSIM_C1, L.SSIM_C2) == (D.SSIM_C1, D.SSIM_C2) and SC.CLAMP == D.SSIM_TRAIN_DEN_FLOOR


@pytest.mark.parametrize("va, vb", [(0.0, 0.0), (0.3, 0.3), (0.0, 1.0)])
def test_constant_images_including_a_clamped_denominator(va, vb):
    # equal constants give SSIM 1 (the denominator is then C1 C2 at its smallest); 0 against 1 a tiny SSIM
    a = torch.full((9, 11, 3), va, dtype=torch.float64)
    b = torch.full((9, 11, 3), vb, dtype=torch.float64)
    ref = _value_and_grads(lambda x, y: L.ssim_map(x, y).mean(), a, b)
    got = _value_and_grads(lambda x, y: ssim_mean_cpu(x, y, _window(), L.SSIM_C1, L.SSIM_C2), a, b)
    assert got[0] == pytest.approx(ref[0], rel=1e-12, abs=1e-15)
    torch.testing.assert_close(got[1], ref[1], rtol=1e-9, atol=1e-15)


def _ssim_reference(a, b, c1, c2):
    """SSIM mean written out with the 2D window and F.conv2d (autograd gives its gradient)."""
    import torch.nn.functional as F
    x, y = a.permute(2, 0, 1)[:, None], b.permute(2, 0, 1)[:, None]
    w = L._gaussian_window(11, 1.5, 1, "cpu", a.dtype)
    mu1, mu2 = F.conv2d(x, w, padding=5), F.conv2d(y, w, padding=5)
    s1 = F.conv2d(x * x, w, padding=5) - mu1 ** 2
    s2 = F.conv2d(y * y, w, padding=5) - mu2 ** 2
    s12 = F.conv2d(x * y, w, padding=5) - mu1 * mu2
    den = (mu1 ** 2 + mu2 ** 2 + c1) * (s1 + s2 + c2)
    return ((2 * mu1 * mu2 + c1) * (2 * s12 + c2) / den.clamp_min(1e-12)).mean()


def test_a_clamped_denominator_passes_no_gradient_through_it():
    # with C1 = C2 = 0, pixels whose window sees only zeros have denominator 0 (clamped to 1e-12); a
    # patch elsewhere keeps the others unclamped
    a = torch.zeros(30, 30, 2, dtype=torch.float64)
    b = torch.zeros(30, 30, 2, dtype=torch.float64)
    a[2:6, 3:8] = 0.7
    b[3:7, 2:6] = 0.4
    ref = _value_and_grads(lambda x, y: _ssim_reference(x, y, 0.0, 0.0), a, b)
    got = _value_and_grads(lambda x, y: ssim_mean_cpu(x, y, _window(), 0.0, 0.0), a, b)
    assert got[0] == pytest.approx(ref[0], rel=1e-9)
    for g_ref, g_got in zip(ref[1:], got[1:]):
        torch.testing.assert_close(g_got, g_ref, rtol=1e-8, atol=1e-10)


def test_gradient_matches_finite_differences():
    a, b = _pair(6, 7, 2, seed=3)
    a.requires_grad_(True)
    b.requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x, y: ssim_mean_cpu(x, y, _window(), L.SSIM_C1, L.SSIM_C2), (a, b),
                                    eps=1e-6, atol=1e-7)


def test_float32_is_as_close_to_float64_as_the_pytorch_float32_version():
    a, b = _pair(64, 80, 3, seed=5)
    ref = _value_and_grads(lambda x, y: L.ssim_map(x, y).mean(), a, b)
    torch32 = _value_and_grads(lambda x, y: L.ssim_map(x, y).mean(), a.float(), b.float())
    ours = _value_and_grads(lambda x, y: ssim_mean_cpu(x, y, _window(torch.float32), L.SSIM_C1, L.SSIM_C2),
                            a.float(), b.float())
    assert ours[1].dtype == torch.float32
    err_torch = float((torch32[1].double() - ref[1]).abs().max())
    err_ours = float((ours[1].double() - ref[1]).abs().max())
    assert err_ours <= 2.0 * err_torch + 1e-12
    assert abs(ours[0] - ref[0]) <= 2.0 * abs(torch32[0] - ref[0]) + 1e-7


def test_the_loss_is_bit_identical_for_any_thread_count():
    a, b = _pair(50, 60, 3, seed=9, dtype=torch.float32)
    before = numba.get_num_threads()
    outs = []
    try:
        for n in (1, 2):
            torch.set_num_threads(n)    # ssim_cpu follows torch's thread count
            outs.append(_value_and_grads(lambda x, y: ssim_mean_cpu(x, y, _window(torch.float32), L.SSIM_C1,
                                                                    L.SSIM_C2), a, b))
    finally:
        torch.set_num_threads(before)
    assert outs[0][0] == outs[1][0]
    assert torch.equal(outs[0][1], outs[1][1]) and torch.equal(outs[0][2], outs[1][2])


def test_losses_ssim_takes_it_on_the_cpu_and_accepts_2d_images():
    a, b = _pair(20, 30, 1, seed=2)
    assert float(L.ssim(a[..., 0], b[..., 0])) == pytest.approx(float(L.ssim_map(a, b).mean()), abs=1e-13)
    with pytest.raises(ValueError, match="shapes differ"):
        L.ssim(a, b[:-1])


def _blur_in_tap_order(x: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Zero-padded separable blur of a (H, W) map, each output 0 + its in-range taps added in tap
    order, rows then columns, in x's dtype (numpy: no fused multiply-add)."""
    r = g.size // 2

    def along(m, axis):
        m = np.moveaxis(m, axis, 0)
        out = np.zeros_like(m)
        for t in range(g.size):
            off = t - r
            lo, hi = max(0, -off), min(m.shape[0], m.shape[0] - off)
            out[lo:hi] = out[lo:hi] + g[t] * m[lo + off:hi + off]
        return np.moveaxis(out, 0, axis)
    return along(along(x, 1), 0)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("shape", [(40, 57, 3), (11, 11, 1), (10, 30, 2), (30, 10, 1), (12, 12, 1)])
def test_the_written_out_11_tap_blur_adds_in_tap_order(shape, dtype):
    """The 11-tap path of the statistics' blur (the sum written out) gives the bits of the tap-order
    loop it replaced, inner pixels and borders, for maps with zeros, negatives and mixed magnitudes."""
    rng = np.random.default_rng(4)
    h, w, c = shape
    a = (rng.standard_normal(shape) * 10.0 ** rng.integers(-4, 3, shape)).astype(dtype)
    b = rng.random(shape).astype(dtype)
    a[0, :3] = 0.0
    a[-1, -2:] = -0.0
    g = _window(torch.float32 if dtype == np.float32 else torch.float64)
    st = np.empty((5 * c, h, w), dtype)
    SC._blur_stats(a, b, g, st)
    for ch in range(c):
        x, y = a[..., ch], b[..., ch]
        for kind, m in enumerate((x, y, x * x, y * y, x * y)):
            want = _blur_in_tap_order(m, g)
            assert np.array_equal(st[5 * ch + kind], want), (ch, kind)
            assert not np.any(np.signbit(st[5 * ch + kind]) & (st[5 * ch + kind] == 0))   # 0 + ...: never -0
