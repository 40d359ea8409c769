"""Scale-free depth terms: the same scene scaled by 10x gives the same weighted GaussianDS terms, and
the device (masked) scale-shift agrees with the float64 reference solver."""
import math

import numpy as np
import pytest
import torch

from gsbench.camera import Camera
from gsbench.gaussians import GaussianField
from gsbench.render import render
from gsbench.train.losses import depth_loss, normalised_depth, solve_scale_shift, tv_loss

LAM = {"depth": 0.01, "tv": 1.5}


def _scene(scale: float):
    g = torch.Generator().manual_seed(0)
    n = 300
    means = torch.rand(n, 3, generator=g) * torch.tensor([2.0, 1.5, 1.0]) - torch.tensor([1.0, 0.75, -2.5])
    field = GaussianField(means * scale, torch.full((n, 3), math.log(0.08 * scale)),
                          torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1), torch.full((n,), 1.5),
                          torch.rand(n, 3, generator=g))
    K = np.array([[40.0, 0, 24], [0, 40.0, 18], [0, 0, 1]])
    w2c = np.eye(4)
    w2c[:3, 3] = np.array([0.1, -0.05, 0.3]) * scale
    return field, Camera(K, w2c, 48, 36)


def _terms(scale: float, form: str, kind: str, normalise: bool = True) -> dict:
    field, cam = _scene(scale)
    out = render(field, cam, backend="torch")
    d = normalised_depth(out.depth, out.alpha) if normalise else out.depth
    ref = render(*_scene(1.0), backend="torch").depth.detach()    # the prior knows nothing of the scale
    prior = (1.0 / ref.clamp_min(1e-3)) if kind == "disparity" else 3.0 * ref + 0.2   # scale-ambiguous prior
    prior = prior + 0.05 * torch.sin(torch.arange(prior.numel()).reshape(prior.shape).float())
    dt = depth_loss(form, d, prior, ref > 1e-3, kind)
    return {"depth": LAM["depth"] * float(dt.loss), "tv": LAM["tv"] * float(tv_loss(d))}


@pytest.mark.parametrize("form,kind", [("scale_shift", "disparity"), ("scale_shift", "depth"), ("pearson", "depth"),
                                       ("minmax", "disparity")])
def test_scene_scaled_10x_gives_same_weighted_terms(form, kind):
    a, b = _terms(1.0, form, kind), _terms(10.0, form, kind)
    assert a["depth"] > 0 and a["tv"] > 0
    for k in a:
        assert b[k] == pytest.approx(a[k], rel=2e-3), (k, a, b)


def test_without_normalisation_the_terms_follow_the_scale():
    """The check above bites: the raw rendered depth's TV grows with the scene."""
    a, b = _terms(1.0, "scale_shift", "depth", False), _terms(10.0, "scale_shift", "depth", False)
    assert b["tv"] > 5 * a["tv"]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_masked_scale_shift_matches_reference(seed):
    rng = np.random.default_rng(seed)
    D = torch.tensor(rng.uniform(0.5, 4.0, (20, 24)), dtype=torch.float32)
    prior = rng.uniform(0.1, 2.0, D.shape).astype(np.float32)
    valid = rng.random(D.shape) > 0.3
    t = depth_loss("scale_shift", D, prior, valid, "depth")
    ref = solve_scale_shift(prior, D.numpy(), valid)
    assert bool(t.ok) and ref.ok
    assert float(t.s) == pytest.approx(ref.s, rel=1e-6) and float(t.t) == pytest.approx(ref.t, rel=1e-6, abs=1e-9)
    res = np.abs(D.numpy().astype(np.float64) - (ref.s * prior + ref.t))[valid].mean()
    assert float(t.loss) == pytest.approx(res, rel=1e-5)


def test_skipped_view_has_finite_zero_gradient():
    D = torch.full((6, 6), 2.0, requires_grad=True)
    t = depth_loss("scale_shift", D, np.full((6, 6), 1.0, np.float32), np.ones((6, 6), bool), "disparity")
    t.loss.backward()
    assert not bool(t.ok) and float(t.loss.detach()) == 0.0
    assert torch.isfinite(D.grad).all() and float(D.grad.abs().sum()) == 0.0


def test_normalised_depth_extremes_are_finite():
    for v in (0.0, 1e-30, 1e30):
        d = normalised_depth(torch.full((4, 4), v), torch.zeros(4, 4) if v == 0.0 else torch.ones(4, 4))
        assert torch.isfinite(d).all()
