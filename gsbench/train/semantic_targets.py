"""Semantic targets shared by gaussiands and twostage: autoencoder on mask features, per-pixel latents.

S(u, v) = encoder(feature of the mask that covers (u, v)); pixels outside every mask (track id -1)
have no target and are left out of L_sem and L_ds.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from gsbench.train.autoencoder import FeatureAutoencoder, train_autoencoder
from gsbench.train.residency import DEVICE, place


@dataclass
class SemanticTargets:
    latents: dict[int, torch.Tensor]     # view id -> (H, W, d)
    has_target: dict[int, torch.Tensor]  # view id -> (H, W) bool


def fit_autoencoder(mask_features: dict, ae_cfg: dict, latent_dim: int, seed: int) -> tuple[FeatureAutoencoder, dict]:
    """Train the AE on every (view, track) mask feature of the scene (sorted keys: deterministic)."""
    if not mask_features:
        raise ValueError("semantic training needs mask features, but the priors produced none")
    keys = sorted(mask_features)
    feats = np.stack([np.asarray(mask_features[k], dtype=np.float32).reshape(-1) for k in keys])
    return train_autoencoder(feats, latent_dim, ae_cfg.get("hidden", (256, 128, 64, 32)),
                             int(ae_cfg.get("epochs", 200)), float(ae_cfg.get("lr", 1e-3)), seed)


def semantic_targets(masks: dict, mask_features: dict, ae_cfg: dict, latent_dim: int, seed: int,
                     ae_state: dict | None, sizes: dict[int, tuple[int, int]], device: torch.device | str,
                     on: str) -> tuple[FeatureAutoencoder, dict, SemanticTargets]:
    """The autoencoder fitted on the mask features (or restored from `ae_state` on resume), moved to
    `device`, and the per-view latent targets it encodes: what GaussianDS and twostage both start from."""
    ae, stats = fit_autoencoder(mask_features, ae_cfg, latent_dim, seed)
    if ae_state is not None:
        ae.load_state_dict(ae_state)
    ae = ae.to(device)
    return ae, stats, build_targets(masks, mask_features, ae, sizes, device=device, on=on)


def build_targets(masks: dict, mask_features: dict, ae: FeatureAutoencoder, sizes: dict[int, tuple[int, int]],
                  device: torch.device | str = "cpu", on: str = DEVICE) -> SemanticTargets:
    """Per-view latent target maps (built once, then kept on `device`, or on the host with on="host":
    gsbench/train/residency.py). `sizes`: view id -> (W, H)."""
    lat, has = {}, {}
    for v, (W, H) in sizes.items():
        m = masks.get(v)
        d = ae.latent_dim
        S = torch.zeros(H, W, d)
        hv = torch.zeros(H, W, dtype=torch.bool)
        if m is not None:
            m = np.asarray(m)
            if m.shape != (H, W):
                raise ValueError(f"mask of view {v} has shape {m.shape}, expected {(H, W)} (training resolution)")
            ids = [int(t) for t in np.unique(m) if t >= 0]
            have = [t for t in ids if (v, t) in mask_features]
            if have:
                f = torch.as_tensor(np.stack([np.asarray(mask_features[(v, t)], dtype=np.float32) for t in have]))
                with torch.no_grad():
                    z = ae.encode(f.to(next(ae.parameters()).device)).cpu()
                mt = torch.as_tensor(m.astype(np.int64))
                for j, t in enumerate(have):
                    sel = mt == t
                    S[sel] = z[j]
                    hv |= sel
        lat[v], has[v] = S, hv
    return SemanticTargets(place(lat, device, on), place(has, device, on))
