"""gsbench's LPIPS against the official `lpips` package (needs torchvision + lpips, i.e. the
separate models venv; skipped in the core .venv). Random torchvision backbone, the package's
real v0.1 linear layers: both implementations read the same files and must agree."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

pytestmark = pytest.mark.models


@pytest.mark.parametrize("net", ["vgg", "alex"])
def test_matches_official_lpips(net, tmp_path):
    torchvision = pytest.importorskip("torchvision")
    ref_pkg = pytest.importorskip("lpips")
    from gsbench.metrics import lpips

    torch.manual_seed(1)
    tv = torchvision.models.vgg16(weights=None) if net == "vgg" else torchvision.models.alexnet(weights=None)
    name = "vgg16-397923af.pth" if net == "vgg" else "alexnet-owt-7be5be79.pth"
    torch.save(tv.state_dict(), tmp_path / name)
    lin_src = Path(ref_pkg.__file__).parent / "weights" / "v0.1" / f"{net}.pth"
    (tmp_path / "lpips" / "v0.1").mkdir(parents=True)
    shutil.copy(lin_src, tmp_path / "lpips" / "v0.1" / f"{net}.pth")

    ref = ref_pkg.LPIPS(net=net, pretrained=True, pnet_rand=True, verbose=False).eval()
    bounds = (
        [(0, 4), (4, 9), (9, 16), (16, 23), (23, 30)] if net == "vgg" else [(0, 2), (2, 5), (5, 8), (8, 10), (10, 12)]
    )
    ref.net.load_state_dict({f"slice{s}.{k}": v for s, (lo, hi) in enumerate(bounds, 1)
                             for k, v in tv.features.state_dict().items() if lo <= int(k.split(".")[0]) < hi})
    rng = np.random.default_rng(0)
    a = rng.random((64, 80, 3)).astype(np.float32)
    b = np.clip(a + 0.2 * rng.standard_normal(a.shape), 0, 1).astype(np.float32)
    with torch.no_grad():
        expect = float(ref(torch.from_numpy(a).permute(2, 0, 1)[None], torch.from_numpy(b).permute(2, 0, 1)[None],
                           normalize=True))
    got = lpips(a, b, net=net, weights_dir=tmp_path)
    assert got.value == pytest.approx(expect, rel=1e-5)
