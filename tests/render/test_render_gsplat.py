"""The `gsplat` backend: argument mapping (runs everywhere), comparison with `torch` (CUDA only)."""
from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest
import torch

from gsbench.camera import Camera
from gsbench.errors import InputError
from gsbench.gaussians import GaussianField
from gsbench.render import render, resolve_backend
from gsbench.render.gsplat_backend import gsplat_arguments, split_outputs

HAVE_GSPLAT = importlib.util.find_spec("gsplat") is not None
HAVE_CUDA = torch.cuda.is_available()


def _scene(n: int = 120, seed: int = 0, n_feat: int = 3, sh: int = 0):
    g = torch.Generator().manual_seed(seed)
    z = torch.rand(n, generator=g) * 3 + 1.5
    xy = (torch.rand(n, 2, generator=g) - 0.5) * 1.2 * z[:, None]
    colors = torch.randn(n, sh, 3, generator=g) * 0.5 if sh else torch.rand(n, 3, generator=g)
    field = GaussianField(torch.cat([xy, z[:, None]], 1), torch.log(torch.rand(n, 3, generator=g) * 0.12 + 0.02),
                          torch.randn(n, 4, generator=g), torch.randn(n, generator=g) * 2, colors,
                          torch.randn(n, n_feat, generator=g) if n_feat else None)
    w2c = np.eye(4)
    w2c[:3, 3] = [0.1, -0.05, 0.2]
    cam = Camera(np.array([[48.0, 0, 24.0], [0, 48.0, 20.0], [0, 0, 1]]), w2c, 48, 40)
    return field, cam


def test_auto_resolves_gsplat_on_cuda_and_cpu_otherwise(monkeypatch):
    # the one rule (render/backend_choice.py) picks gsplat on CUDA where gsplat can render (faked here;
    # tests/methods/test_device.py checks the torch fallback where it cannot)
    import gsbench.render.backend_choice as D
    monkeypatch.setattr(D, "gsplat_available", lambda: True)
    assert resolve_backend("auto", torch.device("cuda")) == "gsplat"
    assert resolve_backend("auto", torch.device("cpu")) == "cpu"


def test_arguments_map_field_and_camera():
    field, cam = _scene(sh=4)
    a = gsplat_arguments(field, cam)
    assert a["render_mode"] == "RGB+D"          # accumulated depth sum w z, not expected depth
    assert a["sh_degree"] is None and a["packed"] is False and a["rasterize_mode"] == "classic"
    assert a["eps2d"] == 0.3 and a["near_plane"] == 0.01 and a["tile_size"] == 16 and a["backgrounds"] is None
    assert a["colors"].shape == (120, 3 + 3)
    assert torch.allclose(a["colors"][:, 3:], field.features)
    # SH evaluated towards each Gaussian from the camera centre (+0.5, clamped at 0)
    centre = torch.as_tensor(cam.center, dtype=torch.float32)
    assert torch.allclose(a["colors"][:, :3], field.rgb(centre))
    assert torch.all(a["colors"][:, :3] >= 0)
    np.testing.assert_allclose(a["viewmats"][0].numpy(), cam.world_to_camera, rtol=1e-6)
    np.testing.assert_allclose(a["Ks"][0].numpy(), cam.K, rtol=1e-6)
    assert torch.allclose(a["quats"].norm(dim=1), torch.ones(120))
    assert torch.allclose(a["scales"], torch.exp(field.log_scales))
    assert a["width"] == 48 and a["height"] == 40


def test_split_outputs_channels_and_background():
    H, W, d = 2, 3, 2
    cols = torch.arange(H * W * (3 + d + 1), dtype=torch.float32).reshape(1, H, W, 3 + d + 1)
    alph = torch.full((1, H, W, 1), 0.25)
    rgb, depth, feats, alpha = split_outputs(cols, alph, d, torch.tensor([1.0, 2.0, 4.0]), torch.float64)
    assert rgb.dtype == torch.float64 and feats.shape == (H, W, d) and depth.shape == (H, W)
    assert torch.equal(depth, cols[0, ..., 5].double())
    assert torch.equal(feats, cols[0, ..., 3:5].double())
    assert torch.allclose(rgb[1, 2],
                          cols[0, 1, 2, :3].double() + 0.75 * torch.tensor([1.0, 2.0, 4.0], dtype=torch.float64))
    assert torch.equal(alpha, torch.full((H, W), 0.25, dtype=torch.float64))
    _, _, none_feats, _ = split_outputs(cols[..., 3:], alph, 0, None, torch.float32)
    assert none_feats is None


@pytest.mark.skipif(HAVE_GSPLAT and HAVE_CUDA, reason="gsplat and CUDA are available")
def test_clear_error_without_gsplat_or_cuda():
    field, cam = _scene()
    with pytest.raises(InputError, match="gsplat|CUDA"):
        render(field, cam, backend="gsplat")


@pytest.mark.cuda
@pytest.mark.skipif(not (HAVE_GSPLAT and HAVE_CUDA), reason="needs CUDA and gsplat (extra `cuda`)")
@pytest.mark.parametrize("seed,sh", [(0, 0), (1, 4)])
def test_gsplat_matches_torch(seed, sh):
    field, cam = _scene(seed=seed, sh=sh)
    bg = torch.tensor([0.2, 0.3, 0.4])

    def run(backend, device):
        leaf = GaussianField(**{k: (None if v is None else v.detach().to(device).clone().requires_grad_(True))
                                for k, v in field.tensors().items()})
        out = render(leaf, cam, backend=backend, background=bg.to(device))
        g = torch.Generator().manual_seed(5)
        parts = [out.rgb, out.depth, out.alpha, out.features]
        loss = sum((p * torch.randn(p.shape, generator=g).to(device)).sum() for p in parts)
        loss.backward()
        grads = {k: v.grad.cpu() for k, v in leaf.tensors().items() if v is not None}
        grads["means2d"] = out.means2d.grad.cpu()
        return out, grads

    og, gg = run("gsplat", "cuda")
    ot, gt = run("torch", "cpu")
    assert og.backend == "gsplat"
    for k in ("rgb", "depth", "alpha", "features"):
        err = (getattr(og, k).detach().cpu() - getattr(ot, k).detach()).abs().max().item()
        assert err <= 1e-4, f"{k}: {err}"
    for k, y in gt.items():
        ref = y.abs().max().item()
        err = (gg[k] - y).abs().max().item()
        assert err <= 1e-3 * ref + 1e-6, f"{k}: rel {err / max(ref, 1e-30):.3g}"
    assert math.isfinite(float(og.rgb.sum()))
