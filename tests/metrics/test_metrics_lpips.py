"""LPIPS: absent weights give None with a reason; random weights run end to end; the weight
files' key mapping is checked against an independent functional forward pass."""
from __future__ import annotations

import importlib.util

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from gsbench.errors import InputError
from gsbench.metrics import METRIC_IMPL, build_lpips_network, find_lpips_weights, lpips

# torchvision layer indices of the conv layers (facts of torchvision's vgg16 / alexnet)
VGG_CONVS = {0: (3, 64), 2: (64, 64), 5: (64, 128), 7: (128, 128), 10: (128, 256), 12: (256, 256),
             14: (256, 256), 17: (256, 512), 19: (512, 512), 21: (512, 512), 24: (512, 512),
             26: (512, 512), 28: (512, 512)}
ALEX_CONVS = {0: (3, 64, 11), 3: (64, 192, 5), 6: (192, 384, 3), 8: (384, 256, 3), 10: (256, 256, 3)}


@pytest.fixture
def no_weights(tmp_path, monkeypatch):
    monkeypatch.setenv("GSBENCH_WEIGHTS", str(tmp_path / "empty"))
    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "torchhome"))
    return tmp_path


def _images(h=40, w=48, seed=0):
    rng = np.random.default_rng(seed)
    a = rng.random((h, w, 3))
    return a, np.clip(a + 0.2 * rng.standard_normal(a.shape), 0, 1)


def test_absent_weights_give_none_with_reason(no_weights):
    if importlib.util.find_spec("lpips") is not None:
        pytest.skip("an installed lpips package provides the linear layers here")
    a, b = _images()
    for net in ("vgg", "alex"):
        r = lpips(a, b, net=net)
        assert r.value is None
        assert r.reason.startswith("no LPIPS weights") and "GSBENCH_WEIGHTS" in r.reason
        assert r.impl.startswith(f"lpips/{net}/")
    assert find_lpips_weights("vgg")[:2] == (None, None)


@pytest.mark.parametrize("net", ["vgg", "alex"])
def test_random_backbone_runs_end_to_end(net):
    model = build_lpips_network(net, random_init=True, seed=3)
    a, b = _images(32, 36)
    r = lpips(a, b, model=model)
    assert r.value is not None and np.isfinite(r.value) and r.value > 0
    assert "random-init" in r.impl
    assert lpips(a, a, model=model).value == 0.0
    assert lpips(b, a, model=model).value == pytest.approx(r.value, rel=1e-5)
    c = np.clip(a + 0.5 * (b - a), 0, 1)             # halfway image is closer than b
    assert lpips(a, c, model=model).value < r.value


def _write_weights(folder, net, seed=0):
    """Files in the exact formats we read: a torchvision state_dict and lpips' lin weights."""
    g = torch.Generator().manual_seed(seed)
    sd = {}
    if net == "vgg":
        for i, (ci, co) in VGG_CONVS.items():
            sd[f"features.{i}.weight"] = torch.randn(co, ci, 3, 3, generator=g) * (2 / (9 * ci)) ** 0.5
            sd[f"features.{i}.bias"] = torch.randn(co, generator=g) * 0.01
        sd["classifier.0.weight"] = torch.zeros(4, 4)    # present in the real file, ignored
        name, chans = "vgg16-397923af.pth", [64, 128, 256, 512, 512]
    else:
        for i, (ci, co, k) in ALEX_CONVS.items():
            sd[f"features.{i}.weight"] = torch.randn(co, ci, k, k, generator=g) * (2 / (k * k * ci)) ** 0.5
            sd[f"features.{i}.bias"] = torch.randn(co, generator=g) * 0.01
        name, chans = "alexnet-owt-7be5be79.pth", [64, 192, 384, 256, 256]
    lin = {f"lin{i}.model.1.weight": torch.rand(1, c, 1, 1, generator=g) for i, c in enumerate(chans)}
    folder.mkdir(parents=True, exist_ok=True)
    torch.save(sd, folder / name)
    (folder / "lpips" / "v0.1").mkdir(parents=True, exist_ok=True)
    torch.save(lin, folder / "lpips" / "v0.1" / f"{net}.pth")
    return sd, lin


def _reference(net, sd, lin, a, b):
    """LPIPS written functionally from the published definition, independent of the module."""
    def feats(x):
        x = (x - torch.tensor([-0.030, -0.088, -0.188]).view(1, 3, 1, 1)) / torch.tensor([0.458, 0.448, 0.450]).view(
            1, 3, 1, 1
        )
        out = []
        if net == "vgg":
            blocks = [[0, 2], [5, 7], [10, 12, 14], [17, 19, 21], [24, 26, 28]]
            for bi, convs in enumerate(blocks):
                if bi:
                    x = F.max_pool2d(x, 2, 2)
                for i in convs:
                    x = F.relu(F.conv2d(x, sd[f"features.{i}.weight"], sd[f"features.{i}.bias"], padding=1))
                out.append(x)
        else:
            x = F.relu(F.conv2d(x, sd["features.0.weight"], sd["features.0.bias"], stride=4, padding=2))
            out.append(x)
            x = F.relu(F.conv2d(F.max_pool2d(x, 3, 2), sd["features.3.weight"], sd["features.3.bias"], padding=2))
            out.append(x)
            x = F.relu(F.conv2d(F.max_pool2d(x, 3, 2), sd["features.6.weight"], sd["features.6.bias"], padding=1))
            out.append(x)
            x = F.relu(F.conv2d(x, sd["features.8.weight"], sd["features.8.bias"], padding=1))
            out.append(x)
            x = F.relu(F.conv2d(x, sd["features.10.weight"], sd["features.10.bias"], padding=1))
            out.append(x)
        return out

    t = lambda im: torch.from_numpy(im).float().permute(2, 0, 1)[None] * 2 - 1  # noqa: E731
    total = 0.0
    for i, (f0, f1) in enumerate(zip(feats(t(a)), feats(t(b)))):
        n0 = f0 / (f0.pow(2).sum(1, keepdim=True).sqrt() + 1e-10)
        n1 = f1 / (f1.pow(2).sum(1, keepdim=True).sqrt() + 1e-10)
        total += float((F.conv2d((n0 - n1) ** 2, lin[f"lin{i}.model.1.weight"])).mean())
    return total


@pytest.mark.parametrize("net", ["vgg", "alex"])
def test_weight_files_load_and_match_functional_reference(net, no_weights, monkeypatch):
    folder = no_weights / "weights"
    sd, lin = _write_weights(folder, net)
    a, b = _images(32, 40, seed=1)
    r = lpips(a, b, net=net, weights_dir=folder)
    assert r.reason is None and "random" not in r.impl
    with torch.no_grad():
        ref = _reference(net, sd, lin, a, b)
    assert r.value == pytest.approx(ref, rel=1e-4)
    # the same files found through $GSBENCH_WEIGHTS
    monkeypatch.setenv("GSBENCH_WEIGHTS", str(folder))
    assert lpips(a, b, net=net).value == pytest.approx(r.value)


def test_corrupt_or_mismatched_files_are_input_errors(no_weights):
    folder = no_weights / "bad"
    _write_weights(folder, "alex")
    (folder / "alexnet-owt-7be5be79.pth").write_bytes(b"not a checkpoint")
    a, b = _images()
    with pytest.raises(InputError, match="alexnet-owt-7be5be79.pth"):
        lpips(a, b, net="alex", weights_dir=folder)
    _write_weights(folder, "alex")
    torch.save({"lin0.model.1.weight": torch.ones(1, 3, 1, 1)}, folder / "lpips" / "v0.1" / "alex.pth")
    with pytest.raises(InputError, match="lin0"):
        lpips(a, b, net="alex", weights_dir=folder)


def test_small_or_grey_images_rejected():
    model = build_lpips_network("alex")
    with pytest.raises(InputError):
        lpips(np.zeros((16, 16, 3)), np.zeros((16, 16, 3)), model=model)
    with pytest.raises(InputError):
        lpips(np.zeros((40, 40)), np.zeros((40, 40)), model=model)


def test_default_impl_is_vgg():
    assert METRIC_IMPL["lpips"].startswith("lpips/vgg/v0.1")
