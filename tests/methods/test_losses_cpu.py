"""The CPU losses (gsbench/train/losses_cpu.py) against the PyTorch code of losses.py, which stays the reference:
values and gradients at float32 and float64, the guards' extreme cases, finite differences, the
dispatch, and results that do not depend on the thread count."""
from __future__ import annotations

import pytest
import torch

from gsbench.train import losses as L

H, W, D = 13, 17, 3
F64 = torch.float64


def _rng(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def _maps(seed: int = 0, h: int = H, w: int = W) -> dict:
    """float64 inputs of the GaussianDS chain (alpha partly below ALPHA_EPS, some depth 0)."""
    g = _rng(seed)
    alpha = torch.rand(h, w, generator=g, dtype=F64) * 0.9 + 0.1
    alpha[0, :4] = 0.5 * L.ALPHA_EPS
    depth = (torch.rand(h, w, generator=g, dtype=F64) * 3 + 1) * alpha
    depth[1, :3] = 0.0
    return dict(depth=depth, alpha=alpha, prior=torch.rand(h, w, generator=g, dtype=F64) + 0.5,
                valid=torch.rand(h, w, generator=g) > 0.1,
                rgb=torch.rand(h, w, 3, generator=g, dtype=F64), gt=torch.rand(h, w, 3, generator=g, dtype=F64),
                feat=torch.randn(h, w, D, generator=g, dtype=F64), S=torch.randn(h, w, D, generator=g, dtype=F64),
                has=torch.rand(h, w, generator=g) > 0.2, edges=torch.rand(h, w, generator=g) > 0.7,
                wts=torch.randn(h, w, generator=g, dtype=F64))


def _run(fn, tensors: list, dtype, fast: bool):
    """fn(*tensors) at dtype (each made a leaf that wants a gradient) with the numba kernels on or off:
    (the result, its loss in float64, the gradients in float64 or None)."""
    before = L.CPU_KERNELS
    L.CPU_KERNELS = fast
    try:
        xs = [t.detach().to(dtype).requires_grad_(True) for t in tensors]
        out = fn(*xs)
        loss = out.loss if isinstance(out, L.DepthTerm) else out
        loss.backward()
    finally:
        L.CPU_KERNELS = before
    return out, loss.detach().double(), [None if x.grad is None else x.grad.double() for x in xs]


_KERNELS = {"_AbsDiffMeanBackward", "_ExpectedBackward", "_TVBackward", "_ScaleShiftLossBackward"}


def _compare(fn, tensors: list, dtype):
    """The numba path at dtype against the PyTorch path in float64 (the inputs rounded to dtype first):
    values to ~1e-5 relative at float32, ~1e-12 at float64; gradients relative to their largest entry."""
    tol = 1e-5 if dtype == torch.float32 else 1e-12
    ref_in = [t.to(dtype).to(F64) for t in tensors]
    out_r, v_r, g_r = _run(fn, ref_in, F64, fast=False)
    out, v, g = _run(fn, tensors, dtype, fast=True)
    loss, loss_r = (x.loss if isinstance(x, L.DepthTerm) else x for x in (out, out_r))
    assert loss.dtype == dtype
    assert _fn_names(loss) & _KERNELS and not _fn_names(loss_r) & _KERNELS
    torch.testing.assert_close(v, v_r, rtol=tol, atol=tol * 1e-3)
    for got, want in zip(g, g_r):
        assert (got is None) == (want is None)
        if want is not None:
            assert torch.isfinite(got).all()
            scale = float(want.abs().max()) or 1.0
            torch.testing.assert_close(got, want, rtol=0, atol=tol * scale)
    return out, out_r, g


def _prior(p: torch.Tensor, dtype):
    """The prior as depth_loss sees it at dtype (it takes the depth's dtype): rounded to dtype, so the
    float64 reference sees the same values. A tensor argument of the loss, but no leaf: a prior that
    wants a gradient takes the PyTorch path."""
    return lambda d: p.to(dtype).to(d.dtype)


def _chain_fns(m: dict, kind: str = "disparity", dtype=F64) -> dict:
    """Each CPU-dispatched loss as fn(*tensors) with its tensors (expected depth weighted so the
    gradient is not uniform; normalised_depth, PyTorch code, through tv_loss)."""
    p = _prior(m["prior"], dtype)
    return {
        "tv_of_normalised_depth": (lambda d, a: L.tv_loss(L.normalised_depth(d, a), 1e-6), [m["depth"], m["alpha"]]),
        "expected_depth": (lambda d, a: (L.expected_depth(d, a) * m["wts"].to(d.dtype)).sum(),
                           [m["depth"], m["alpha"]]),
        "depth_loss": (lambda d: L.depth_loss("scale_shift", d, p(d), m["valid"], kind, 10), [m["depth"]]),
        "tv": (lambda d: L.tv_loss(d, 1e-6), [m["depth"]]),
        "sem": (lambda s, t: L.sem_loss(s, t, m["has"]), [m["feat"], m["S"]]),
        "ds_pixels": (lambda s, t: L.ds_loss(s, t, m["has"], m["edges"], "pixels"), [m["feat"], m["S"]]),
        "ds_edges": (lambda s, t: L.ds_loss(s, t, m["has"], m["edges"], "edges"), [m["feat"], m["S"]]),
    }


# ---------------------------------------------------------------------------- against the PyTorch path
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("name", list(_chain_fns(_maps())))
def test_values_and_gradients_equal_the_pytorch_path(name, dtype):
    fn, tensors = _chain_fns(_maps(1), dtype=dtype)[name]
    _compare(fn, tensors, dtype)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("d", [1, 2, 8])
def test_sem_and_ds_for_other_latent_sizes(d, dtype):
    m, g = _maps(13), _rng(13)
    feat, target = torch.randn(H, W, d, generator=g, dtype=F64), torch.randn(H, W, d, generator=g, dtype=F64)
    _compare(lambda s, t: L.sem_loss(s, t, m["has"]), [feat, target], dtype)
    _compare(lambda s, t: L.ds_loss(s, t, m["has"], m["edges"], "edges"), [feat, target], dtype)


def _term_fields_equal(out, ref):
    assert bool(out.ok) == bool(ref.ok) and out.min_valid == ref.min_valid
    assert out.ok.dtype == torch.bool and out.s.dtype == ref.s.dtype == F64
    assert float(out.n_valid) == float(ref.n_valid) and out.n_valid.dtype == out.loss.dtype
    assert out.reason == ref.reason
    for a, b in ((out.s, ref.s), (out.t, ref.t)):
        assert not a.requires_grad and float(a) == pytest.approx(float(b), rel=1e-6, abs=1e-12)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("kind", ["disparity", "depth", "metric"])
def test_depth_loss_term_fields_equal_the_pytorch_path(kind, dtype):
    m = _maps(2)
    out, ref, _ = _compare(*_chain_fns(m, kind, dtype)["depth_loss"], dtype)
    _term_fields_equal(out, ref)
    assert bool(ref.ok)


def test_depth_loss_accepts_a_numpy_prior_as_the_pytorch_path_does():
    m = _maps(3)
    prior, valid = m["prior"].numpy(), m["valid"].numpy()
    out, ref, _ = _compare(lambda d: L.depth_loss("scale_shift", d, prior, valid, "disparity", 10), [m["depth"]],
                           F64)
    _term_fields_equal(out, ref)


# ---------------------------------------------------------------------------- extreme cases
def _zero_grads(grads):
    for g in grads:
        assert g is not None and torch.isfinite(g).all() and not g.any()


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_nothing_counts_gives_zero_and_zero_gradients(dtype):
    m = _maps(4)
    nobody = torch.zeros(H, W, dtype=torch.bool)
    cases = [(lambda s, t: L.sem_loss(s, t, nobody), [m["feat"], m["S"]]),
             (lambda s, t: L.ds_loss(s, t, nobody, m["edges"]), [m["feat"], m["S"]]),
             (lambda s, t: L.ds_loss(s, t, m["has"], nobody, "edges"), [m["feat"], m["S"]]),
             (lambda d: L.depth_loss("scale_shift", d, _prior(m["prior"], dtype)(d), nobody, "disparity", 10),
              [m["depth"]])]
    for fn, tensors in cases:
        out, out_r, grads = _compare(fn, tensors, dtype)
        assert float((out.loss if isinstance(out, L.DepthTerm) else out).detach()) == 0.0
        _zero_grads(grads)
    assert not bool(out.ok) and float(out.n_valid) == 0.0
    _term_fields_equal(out, out_r)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("case", ["constant", "zero", "few", "uncovered"])
def test_depth_loss_skips_exactly_where_the_pytorch_path_does(case, dtype):
    m = _maps(5)
    depth, prior, valid = m["depth"].clone(), m["prior"].clone(), m["valid"].clone()
    if case == "constant":
        prior[:] = 7.25
    elif case == "zero":
        prior[:] = 0.0
    elif case == "few":
        valid[:] = False
        valid[2, :9] = True                   # 9 < min_valid = 10
    else:
        depth[:] = 0.0                        # D <= DEPTH_EPS everywhere: no usable pixel
    p = _prior(prior, dtype)
    out, ref, grads = _compare(lambda d: L.depth_loss("scale_shift", d, p(d), valid, "disparity", 10), [depth], dtype)
    _term_fields_equal(out, ref)
    assert not bool(out.ok) and float(out.loss.detach()) == 0.0
    _zero_grads(grads)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_depth_loss_of_an_infinite_depth(dtype):
    # 1 / inf = 0 on every pixel: the fit s = t = 0 is exact (ok), the loss 0 and its gradient 0
    m = _maps(5)
    depth = torch.full((H, W), float("inf"), dtype=F64)
    p = _prior(m["prior"], dtype)
    out, ref, grads = _compare(lambda d: L.depth_loss("scale_shift", d, p(d), m["valid"], "disparity", 10), [depth],
                               dtype)
    _term_fields_equal(out, ref)
    assert float(out.loss.detach()) == 0.0 and float(out.s) == 0.0
    _zero_grads(grads)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("mag", [1e-20, 1e20])
@pytest.mark.parametrize("kind", ["disparity", "depth"])
def test_depth_loss_huge_and_tiny_magnitudes(mag, kind, dtype):
    m = _maps(6)
    depth = m["depth"] * (mag if kind == "depth" and mag > 1 else 1.0)   # tiny depth would be unusable
    p = _prior(m["prior"] * mag, dtype)
    out, ref, _ = _compare(lambda d: L.depth_loss("scale_shift", d, p(d), m["valid"], kind, 10), [depth], dtype)
    _term_fields_equal(out, ref)
    assert bool(out.ok)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_expected_depth_with_alpha_below_the_floor_everywhere(dtype):
    m = _maps(7)
    alpha = torch.full((H, W), 0.5 * L.ALPHA_EPS, dtype=F64)
    out, _, grads = _compare(lambda d, a: L.expected_depth(d, a).sum(), [m["depth"], alpha], dtype)
    assert float(out.detach()) == 0.0
    _zero_grads(grads)
    # the floor itself is not covered either; in float32 the floor is float32(ALPHA_EPS), as in PyTorch
    alpha[0, 0] = torch.tensor(L.ALPHA_EPS, dtype=dtype).item()
    ref = _run(lambda d, a: L.expected_depth(d, a).sum(), [m["depth"], alpha], dtype, fast=False)
    got = _run(lambda d, a: L.expected_depth(d, a).sum(), [m["depth"], alpha], dtype, fast=True)
    assert float(ref[1]) == float(got[1]) == 0.0


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_normalised_depth_of_an_empty_render_and_tv_on_flat_maps(dtype):
    zeros = torch.zeros(H, W, dtype=F64)
    out, _, (g_d, g_a) = _compare(lambda d, a: L.tv_loss(L.normalised_depth(d, a), 1e-6), [zeros, zeros], dtype)
    assert g_a is None and torch.isfinite(g_d).all()
    flat = torch.full((H, W), 2.0, dtype=F64)
    flat[5:, :] = 3.0                         # a step: one row of cells with a gradient
    for eps in (1e-6, 0.0):                   # eps = 0: the clamp floor acts on the flat cells
        out, _, grads = _compare(lambda d, e=eps: L.tv_loss(d, e), [flat], dtype)
        assert torch.isfinite(grads[0]).all()
    # differences of ~1e-17: dx^2 + dy^2 < 1e-30, so the floor holds the value and stops the gradient
    tiny = 1e-17 * torch.rand(H, W, generator=_rng(8), dtype=F64)
    out, ref, grads = _compare(lambda d: L.tv_loss(d, 0.0), [tiny], dtype)
    assert float(ref.detach()) == pytest.approx(1e-15) and not grads[0].any()


# ---------------------------------------------------------------------------- finite differences
def _leaf(t):
    return t.detach().clone().requires_grad_(True)


def test_gradcheck_of_the_functions_without_detached_parts():
    m = _maps(9, 7, 9)
    m["alpha"][0, :4] = 0.3                    # keep every alpha away from the floor: a smooth function
    m["depth"][1, :3] = 0.5
    checks = [(L.l1, [m["rgb"], m["gt"]]),
              (L.expected_depth, [m["depth"], m["alpha"]]),
              (lambda d: L.tv_loss(d, 1e-6), [m["depth"]]),
              (lambda s, t: L.sem_loss(s, t, m["has"]), [m["feat"], m["S"]]),
              (lambda s, t: L.ds_loss(s, t, m["has"], m["edges"], "pixels"), [m["feat"], m["S"]]),
              (lambda s, t: L.ds_loss(s, t, m["has"], m["edges"], "edges"), [m["feat"], m["S"]])]
    for fn, tensors in checks:
        assert torch.autograd.gradcheck(fn, [_leaf(t) for t in tensors], eps=1e-6, atol=1e-7)


def test_finite_differences_with_the_detached_parts_held_fixed():
    """normalised_depth's reference and the depth loss's s, t carry no gradient: a finite difference
    with them held at the values the function used (formulas written out here) gives its gradient."""
    m = _maps(10, 7, 9)
    depth, alpha = _leaf(m["depth"] + 0.5), m["alpha"]
    (L.normalised_depth(depth, alpha) * m["wts"]).sum().backward()
    ref = max(float(depth.detach().sum() / alpha.sum()), L.DEPTH_EPS)
    torch.testing.assert_close(depth.grad, m["wts"] / ref, rtol=1e-12, atol=0)

    d = _leaf(m["depth"] + 0.5)
    term = L.depth_loss("scale_shift", d, m["prior"], m["valid"], "disparity", 10)
    term.loss.backward()
    s, t, use = float(term.s), float(term.t), m["valid"] & (m["depth"] + 0.5 > L.DEPTH_EPS)

    def fixed(x):
        return float(((1.0 / x - (s * m["prior"] + t)).abs() * use).sum() / use.sum())

    h = 1e-6
    base = d.detach()
    for i, j in [(0, 0), (3, 4), (6, 8), (2, 7)]:
        up, dn = base.clone(), base.clone()
        up[i, j] += h
        dn[i, j] -= h
        assert float(d.grad[i, j]) == pytest.approx((fixed(up) - fixed(dn)) / (2 * h), rel=1e-6, abs=1e-9)


# ---------------------------------------------------------------------------- dispatch and threads
def _fn_names(t: torch.Tensor) -> set:
    names, todo = set(), [t.grad_fn]
    while todo:
        f = todo.pop()
        if f is not None and type(f).__name__ not in names:
            names.add(type(f).__name__)
            todo.extend(g for g, _ in f.next_functions)
    return names


def test_cpu_float_tensors_take_the_kernels_and_others_the_pytorch_code():
    m = _maps(11)
    f = _leaf(m["feat"]).float()
    assert "_AbsDiffMeanBackward" in _fn_names(L.sem_loss(f, m["S"].float(), m["has"]))
    assert "_AbsDiffMeanBackward" not in _fn_names(L.sem_loss(f.half(), m["S"].half(), m["has"]))
    assert "_AbsDiffMeanBackward" not in _fn_names(L.sem_loss(f, m["S"].float()[:1], m["has"]))   # broadcast
    assert "_AbsDiffMeanBackward" not in _fn_names(L.sem_loss(f, m["S"].float(), m["has"].float()))
    d = _leaf(m["depth"])
    assert "_ScaleShiftLossBackward" in _fn_names(L.depth_loss("scale_shift", d, m["prior"], m["valid"],
                                                               "disparity").loss)
    for form in ("raw_l1", "minmax", "pearson"):
        assert "_ScaleShiftLossBackward" not in _fn_names(L.depth_loss(form, d, m["prior"], m["valid"],
                                                                       "disparity").loss)
    with pytest.raises(ValueError, match="unknown depth prior kind"):
        L.depth_loss("scale_shift", d, m["prior"], m["valid"], "inverse")


def test_the_chain_is_bit_identical_for_one_and_two_threads():
    m = _maps(12, 48, 64)

    def chain(rgb, depth, alpha, feat):
        dn = L.normalised_depth(depth, alpha)
        dt = L.depth_loss("scale_shift", L.expected_depth(dn, alpha), m["prior"], m["valid"], "disparity", 10)
        s = m["S"].float()
        return (0.8 * L.l1(rgb, m["gt"].float()) + 0.01 * dt.loss + 1.5 * L.tv_loss(dn, 1e-6)
                + 5 * L.sem_loss(feat, s, m["has"]) + L.ds_loss(feat, s, m["has"], m["edges"]))

    before = torch.get_num_threads()
    outs = []
    try:
        for n in (1, 2):
            torch.set_num_threads(n)
            outs.append(_run(chain, [m["rgb"], m["depth"], m["alpha"], m["feat"]], torch.float32, fast=True))
    finally:
        torch.set_num_threads(before)
    assert torch.equal(outs[0][1], outs[1][1])
    for a, b in zip(outs[0][2], outs[1][2]):
        assert torch.equal(a, b)
