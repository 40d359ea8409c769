"""The feature autoencoder of GaussianDS: 512 -> 256 -> 128 -> 64 -> 32 -> d, decoder mirrored.

Both the latent and the reconstruction are L2-normalised (cosine geometry, like CLIP features).
It is trained on the scene's mask features (one 512-d unit vector per (view, track)), then frozen;
the per-pixel target is S = encoder(feature of the pixel's mask). Loss: L2 + (1 - cosine) of the
reconstruction, full batch Adam, seeded.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import torch
from torch import nn

from gsbench.train.adam import Adam


def _mlp(dims: Sequence[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(dims) - 1):
        layers.append(nn.Linear(dims[i], dims[i + 1]))
        if i < len(dims) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


def _unit(x: torch.Tensor, inplace: bool = False) -> torch.Tensor:
    """Rows scaled to unit length. inplace: overwrite x (a fresh output nobody else holds, no graph);
    the values are the same either way. The largest magnitude max(max x, -min x) is |x|'s maximum
    without an |x| temporary (evaluation decodes 512-d maps of every pixel); amax and amin are two
    passes but ~5x faster than torch.aminmax's one on the CPU, with the same values."""
    # divide by the largest magnitude first so the norm cannot overflow (float32 inputs ~1e20+)
    m = torch.maximum(x.amax(dim=-1, keepdim=True), -x.amin(dim=-1, keepdim=True)).clamp_min(1e-30)
    x = x.div_(m) if inplace else x / m
    n = x.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return x.div_(n) if inplace else x / n


class FeatureAutoencoder(nn.Module):
    """Encoder in_dim -> hidden... -> d and the mirrored decoder; outputs are unit vectors."""

    def __init__(self, in_dim: int = 512, latent_dim: int = 3, hidden: Sequence[int] = (256, 128, 64, 32)) -> None:
        super().__init__()
        if latent_dim < 1:
            raise ValueError(f"semantic.latent_dim must be >= 1, got {latent_dim}")
        self.in_dim, self.latent_dim, self.hidden = int(in_dim), int(latent_dim), [int(h) for h in hidden]
        self.encoder = _mlp([self.in_dim, *self.hidden, self.latent_dim])
        self.decoder = _mlp([self.latent_dim, *reversed(self.hidden), self.in_dim])

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        y = self.encoder(x)
        return _unit(y, inplace=not y.requires_grad)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        if torch.is_grad_enabled() and (z.requires_grad or any(p.requires_grad for p in self.decoder.parameters())):
            return _unit(self.decoder(z))
        # no graph: the same layers with the ReLUs in place (one (N, width) buffer less per layer)
        y = z
        for layer in self.decoder:
            y = torch.relu_(y) if isinstance(layer, nn.ReLU) else layer(y)
        return _unit(y, inplace=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.decode(self.encode(x))

    def config(self) -> dict:
        return {"in_dim": self.in_dim, "latent_dim": self.latent_dim, "hidden": self.hidden}


def train_autoencoder(features: np.ndarray, latent_dim: int, hidden: Sequence[int] = (256, 128, 64, 32),
                      epochs: int = 200, lr: float = 1e-3, seed: int = 0) -> tuple[FeatureAutoencoder, dict]:
    """Fit the autoencoder on (M, 512) features (full batch); return it frozen and in eval mode."""
    x = np.asarray(features, dtype=np.float32)
    if x.ndim != 2 or x.shape[0] < 1:
        raise ValueError(f"autoencoder needs an (M, D) feature matrix with M >= 1, got shape {x.shape}")
    if not np.isfinite(x).all():
        raise ValueError("autoencoder: mask features contain NaN or inf")
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(seed))
        ae = FeatureAutoencoder(x.shape[1], latent_dim, hidden)
    xt = _unit(torch.from_numpy(x))
    opt = Adam(ae.parameters(), lr=lr)
    loss = torch.tensor(float("nan"))
    # a few hundred rows through a small MLP: one thread is ~10x faster than two contending ones
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        for _ in range(int(epochs)):
            opt.zero_grad(set_to_none=True)
            rec = ae(xt)
            loss = ((rec - xt) ** 2).sum(-1).mean() + (1.0 - (rec * xt).sum(-1)).mean()
            loss.backward()
            opt.step()
    finally:
        torch.set_num_threads(threads)
    ae.eval()
    for p in ae.parameters():
        p.requires_grad_(False)
    with torch.no_grad():
        cos = (ae(xt) * xt).sum(-1)
    stats = {"ae_final_loss": float(loss.detach()), "ae_mean_cosine": float(cos.mean()),
             "ae_min_cosine": float(cos.min()), "ae_n_features": int(x.shape[0])}
    return ae, stats
