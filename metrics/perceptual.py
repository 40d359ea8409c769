"""LPIPS (v0.1) in plain PyTorch: no torchvision, no lpips package import, never a download.

Network (the public LPIPS definition, rebuilt here layer by layer):
  input in [0, 1] -> 2x - 1 -> (x - shift) / scale, shift = (-.030, -.088, -.188),
  scale = (.458, .448, .450) -> backbone taps -> unit-normalise over channels
  (f / (sqrt(sum f^2) + 1e-10)) -> squared difference -> learned 1x1 conv (lin0..lin4, no bias)
  -> spatial mean -> sum over the five taps.
  vgg  (default, the 3DGS convention): torchvision VGG16 `features[0:30]`, taps after the
       ReLUs at indices 3, 8, 15, 22, 29 (relu1_2, relu2_2, relu3_3, relu4_3, relu5_3).
  alex: torchvision AlexNet `features[0:12]`, taps after indices 1, 4, 7, 9, 11 (relu1..relu5).

Weights (both needed; ImageNet backbones are not shipped by any package we may install):
  backbone: a torchvision state_dict, `vgg16-397923af.pth` / `alexnet-owt-7be5be79.pth`, looked up
            in $GSBENCH_WEIGHTS (or `weights_dir`), then in the torch hub cache
            (`torch.hub.get_dir()/checkpoints`).
  linear layers: the lpips package's `weights/v0.1/{vgg,alex}.pth` (keys `lin{i}.model.1.weight`),
            looked up in $GSBENCH_WEIGHTS as `lpips/v0.1/<net>.pth`, `v0.1/<net>.pth` or
            `lpips_<net>.pth`, then inside an installed `lpips` package (located with
            importlib.util.find_spec, never imported: it would import torchvision).
When either file is absent `lpips()` returns an LPIPSResult with value None and the reason;
the report prints "n/a (no LPIPS weights)". A present but unreadable or mismatching file is an
InputError naming the file.

`build_lpips_network(net, random_init=True)` builds the same network with seeded random
weights so the code path can be tested offline; its results carry a "random-init" impl id and
must never be reported.
"""
from __future__ import annotations

import functools
import importlib.util
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from gsbench.errors import InputError

from ._common import finite_float

LPIPS_NETS = ("vgg", "alex")
BACKBONE_FILES = {"vgg": "vgg16-397923af.pth", "alex": "alexnet-owt-7be5be79.pth"}
LPIPS_SHIFT = (-0.030, -0.088, -0.188)
LPIPS_SCALE = (0.458, 0.448, 0.450)
LPIPS_MIN_SIZE = 32
WEIGHTS_ENV = "GSBENCH_WEIGHTS"
#: input range fed to the network: the LPIPS package maps [0, 1] images to [-1, 1] (2x - 1);
#: the 3DGS metrics script feeds the [0, 1] images unscaled. The two give different numbers; the
#: evaluation keeps both (`lpips` = 3DGS's, `lpips_package`).
LPIPS_RANGES = ("lpips-[-1,1]", "3dgs-[0,1]")
LPIPS_DEFAULT_RANGE = "lpips-[-1,1]"


def lpips_impl(net: str, random_init: bool = False, input_range: str = LPIPS_DEFAULT_RANGE) -> str:
    """Implementation id; it names the input range (the two public conventions give different values)."""
    if input_range not in LPIPS_RANGES:
        raise InputError(f"LPIPS input range must be one of {LPIPS_RANGES}, got {input_range!r}")
    base = f"lpips/{net}/v0.1/input{input_range}/gsbench-torch/v2"
    return base + "/random-init-TEST-ONLY" if random_init else base


def _vgg16_layers() -> tuple[list[nn.Module], tuple[int, ...], tuple[int, ...]]:
    cfg = [64, 64, "M", 128, 128, "M", 256, 256, 256, "M", 512, 512, 512, "M", 512, 512, 512]
    layers: list[nn.Module] = []
    cin = 3
    for v in cfg:
        if v == "M":
            layers.append(nn.MaxPool2d(kernel_size=2, stride=2))
        else:
            layers += [nn.Conv2d(cin, v, kernel_size=3, padding=1), nn.ReLU()]
            cin = v
    return layers, (3, 8, 15, 22, 29), (64, 128, 256, 512, 512)


def _alexnet_layers() -> tuple[list[nn.Module], tuple[int, ...], tuple[int, ...]]:
    layers = [
        nn.Conv2d(3, 64, kernel_size=11, stride=4, padding=2), nn.ReLU(),
        nn.MaxPool2d(kernel_size=3, stride=2),
        nn.Conv2d(64, 192, kernel_size=5, padding=2), nn.ReLU(),
        nn.MaxPool2d(kernel_size=3, stride=2),
        nn.Conv2d(192, 384, kernel_size=3, padding=1), nn.ReLU(),
        nn.Conv2d(384, 256, kernel_size=3, padding=1), nn.ReLU(),
        nn.Conv2d(256, 256, kernel_size=3, padding=1), nn.ReLU(),
    ]
    return layers, (1, 4, 7, 9, 11), (64, 192, 384, 256, 256)


class LPIPSNet(nn.Module):
    """Backbone trunk (torchvision layer indices, so state_dict keys map 1:1) + lin0..lin4."""

    def __init__(self, net: str = "vgg") -> None:
        super().__init__()
        if net not in LPIPS_NETS:
            raise InputError(f"lpips net must be one of {LPIPS_NETS}, got {net!r}")
        layers, taps, chans = _vgg16_layers() if net == "vgg" else _alexnet_layers()
        self.net = net
        self.features = nn.Sequential(*layers)
        self.taps = taps
        self.lins = nn.ModuleList(nn.Conv2d(c, 1, kernel_size=1, bias=False) for c in chans)
        self.register_buffer("shift", torch.tensor(LPIPS_SHIFT).view(1, 3, 1, 1))
        self.register_buffer("scale", torch.tensor(LPIPS_SCALE).view(1, 3, 1, 1))
        self.random_init = False
        self.sources: dict[str, str] = {}
        self.eval()
        self.requires_grad_(False)

    def _taps(self, x: torch.Tensor) -> list[torch.Tensor]:
        out = []
        h = (x - self.shift) / self.scale
        last = self.taps[-1]
        for i, layer in enumerate(self.features):
            h = layer(h)
            if i in self.taps:
                out.append(h)
            if i == last:
                break
        return out

    @staticmethod
    def _unit(f: torch.Tensor, eps: float = 1e-10) -> torch.Tensor:
        return f / (torch.sqrt(torch.sum(f * f, dim=1, keepdim=True)) + eps)

    def forward(self, x0: torch.Tensor, x1: torch.Tensor) -> torch.Tensor:
        """x0, x1: (N, 3, H, W) in [-1, 1] -> (N,) distances."""
        total = torch.zeros(x0.shape[0], dtype=x0.dtype, device=x0.device)
        for f0, f1, lin in zip(self._taps(x0), self._taps(x1), self.lins):
            d = (self._unit(f0) - self._unit(f1)) ** 2
            total = total + lin(d).mean(dim=(1, 2, 3))
        return total


def build_lpips_network(net: str = "vgg", *, random_init: bool = True, seed: int = 0) -> LPIPSNet:
    """The LPIPS network with seeded random weights (tests only; never a reportable value)."""
    model = LPIPSNet(net)
    if random_init:
        g = torch.Generator().manual_seed(seed)
        with torch.no_grad():
            for m in model.features:
                if isinstance(m, nn.Conv2d):
                    fan_in = m.in_channels * m.kernel_size[0] * m.kernel_size[1]
                    m.weight.copy_(torch.randn(m.weight.shape, generator=g) * (2.0 / fan_in) ** 0.5)
                    m.bias.zero_()
            for lin in model.lins:  # LPIPS lin weights are non-negative
                lin.weight.copy_(torch.rand(lin.weight.shape, generator=g) / lin.in_channels)
        model.random_init = True
        model.sources = {"backbone": f"random(seed={seed})", "lin": f"random(seed={seed})"}
    return model


def _weights_dir(weights_dir: str | os.PathLike | None) -> Path | None:
    if weights_dir is not None:
        return Path(weights_dir)
    env = os.environ.get(WEIGHTS_ENV)
    return Path(env) if env else None


def find_lpips_weights(net: str = "vgg", weights_dir: str | os.PathLike | None = None
                       ) -> tuple[Path | None, Path | None, list[str]]:
    """(backbone file, linear-layer file, places searched); a file is None when not found."""
    if net not in LPIPS_NETS:
        raise InputError(f"lpips net must be one of {LPIPS_NETS}, got {net!r}")
    wdir = _weights_dir(weights_dir)
    name = BACKBONE_FILES[net]
    backbone_c: list[Path] = []
    lin_c: list[Path] = []
    if wdir is not None:
        backbone_c += [wdir / name, wdir / "checkpoints" / name]
        lin_c += [wdir / "lpips" / "v0.1" / f"{net}.pth", wdir / "v0.1" / f"{net}.pth", wdir / f"lpips_{net}.pth"]
    backbone_c.append(Path(torch.hub.get_dir()) / "checkpoints" / name)
    spec = importlib.util.find_spec("lpips")
    if spec is not None and spec.submodule_search_locations:
        for loc in spec.submodule_search_locations:
            lin_c.append(Path(loc) / "weights" / "v0.1" / f"{net}.pth")
    searched = [str(p) for p in backbone_c + lin_c]
    backbone = next((p for p in backbone_c if p.is_file()), None)
    lin = next((p for p in lin_c if p.is_file()), None)
    return backbone, lin, searched


def _load_state(path: Path) -> dict:
    try:
        sd = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # torch raises several types for corrupt files
        raise InputError(f"{path}: cannot read LPIPS weights ({type(e).__name__}: {e})") from None
    if not isinstance(sd, dict):
        raise InputError(f"{path}: expected a state_dict, got {type(sd).__name__}")
    return sd


def load_lpips_weights(model: LPIPSNet, backbone: Path, lin: Path) -> LPIPSNet:
    """Copy a torchvision backbone state_dict and LPIPS v0.1 lin weights into `model`."""
    sd = _load_state(backbone)
    n = len(model.features)
    feats = {}
    for k, v in sd.items():
        parts = k.split(".")
        if len(parts) == 3 and parts[0] == "features" and parts[1].isdigit() and int(parts[1]) < n:
            feats[f"{parts[1]}.{parts[2]}"] = v
    try:
        model.features.load_state_dict(feats, strict=True)
    except RuntimeError as e:
        raise InputError(f"{backbone}: not a torchvision {model.net} state_dict ({str(e).splitlines()[0]})") from None
    ld = _load_state(lin)
    for i, layer in enumerate(model.lins):
        key = f"lin{i}.model.1.weight"
        if key not in ld or tuple(ld[key].shape) != tuple(layer.weight.shape):
            got = tuple(ld[key].shape) if key in ld else "missing"
            raise InputError(f"{lin}: key {key} should have shape {tuple(layer.weight.shape)}, got {got}")
        with torch.no_grad():
            layer.weight.copy_(ld[key])
    model.random_init = False
    model.sources = {"backbone": str(backbone), "lin": str(lin)}
    return model


@functools.lru_cache(maxsize=4)
def _cached_model(net: str, backbone: str, lin: str) -> LPIPSNet:
    return load_lpips_weights(LPIPSNet(net), Path(backbone), Path(lin))


def load_lpips(net: str = "vgg", weights_dir: str | os.PathLike | None = None) -> tuple[LPIPSNet | None, str | None]:
    """(model, None) when both weight files are found, else (None, reason). Never downloads."""
    backbone, lin, searched = find_lpips_weights(net, weights_dir)
    if backbone is None or lin is None:
        missing = []
        if backbone is None:
            missing.append(f"backbone {BACKBONE_FILES[net]}")
        if lin is None:
            missing.append(f"linear layers v0.1/{net}.pth")
        return None, (f"no LPIPS weights: {' and '.join(missing)} not found (set {WEIGHTS_ENV}; "
                      f"searched {', '.join(searched)})")
    return _cached_model(net, str(backbone), str(lin)), None


@dataclass
class LPIPSResult:
    value: float | None
    reason: str | None      # why value is None
    impl: str
    net: str


def _to_batch(img: Any, name: str, input_range: str) -> torch.Tensor:
    a = finite_float(img, name, np.float32)
    if a.ndim != 3 or a.shape[2] != 3:
        raise InputError(f"{name}: LPIPS needs an (H, W, 3) RGB image, got shape {a.shape}")
    if min(a.shape[:2]) < LPIPS_MIN_SIZE:
        raise InputError(f"{name}: LPIPS needs images of at least {LPIPS_MIN_SIZE} px per side, got {a.shape[:2]}")
    t = torch.from_numpy(np.clip(a, 0.0, 1.0)).permute(2, 0, 1)[None]
    return t * 2.0 - 1.0 if input_range == "lpips-[-1,1]" else t


def lpips(pred: Any, gt: Any, *, net: str = "vgg", model: LPIPSNet | None = None,
          weights_dir: str | os.PathLike | None = None, device: str | torch.device = "cpu",
          input_range: str = LPIPS_DEFAULT_RANGE) -> LPIPSResult:
    """LPIPS distance of two (H, W, 3) images in [0, 1]; lower is better. `input_range` says what the
    network sees: "lpips-[-1,1]" (2x - 1, the LPIPS package) or "3dgs-[0,1]" (unscaled, 3DGS's script).

    `model` overrides the weight lookup (e.g. a network from `build_lpips_network`).
    """
    if input_range not in LPIPS_RANGES:
        raise InputError(f"LPIPS input range must be one of {LPIPS_RANGES}, got {input_range!r}")
    if model is None:
        model, reason = load_lpips(net, weights_dir)
        if model is None:
            return LPIPSResult(None, reason, lpips_impl(net, input_range=input_range), net)
    x0 = _to_batch(pred, "pred image", input_range)
    x1 = _to_batch(gt, "gt image", input_range)
    if x0.shape != x1.shape:
        raise InputError(f"pred image has shape {tuple(x0.shape[2:])} but gt image has {tuple(x1.shape[2:])}")
    model = model.to(device)
    with torch.no_grad():
        v = float(model(x0.to(device), x1.to(device))[0])
    return LPIPSResult(v, None, lpips_impl(model.net, model.random_init, input_range), model.net)
