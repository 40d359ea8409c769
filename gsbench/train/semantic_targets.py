"""Semantic targets shared by gaussiands and twostage: autoencoder on mask features, per-pixel latents.

S(u, v) = encoder(feature of the mask that covers (u, v)); pixels outside every mask (track id -1)
have no target and are left out of L_sem and L_ds.
"""
from __future__ import annotations

import hashlib
import logging
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import torch

from gsbench.environment import cpu_facts
from gsbench.priors.cache import PriorCache, cache_key
from gsbench.train.autoencoder import FeatureAutoencoder, train_autoencoder
from gsbench.train.residency import DEVICE, place

log = logging.getLogger(__name__)

# the fit's cache entries: bump when train_autoencoder's arithmetic changes
AE_CACHE_VERSION = 1


@dataclass
class SemanticTargets:
    latents: dict[int, torch.Tensor]     # view id -> (H, W, d)
    has_target: dict[int, torch.Tensor]  # view id -> (H, W) bool


def fit_autoencoder(mask_features: dict, ae_cfg: dict, latent_dim: int, seed: int,
                    cache_dir: Optional[Path] = None) -> tuple[FeatureAutoencoder, dict]:
    """Train the AE on every (view, track) mask feature of the scene (sorted keys: deterministic).

    With `cache_dir` (the priors cache) a fit is kept there and reused by every later run with the same
    features, settings, seed, torch and CPU flags: the fit is seeded and runs on one thread, so the
    restored weights and statistics are the bits a new fit would give (the cells of a grid that differ
    only in their loss weights share one fit, as they share the priors)."""
    if not mask_features:
        raise ValueError("semantic training needs mask features, but the priors produced none")
    keys = sorted(mask_features)
    feats = np.stack([np.asarray(mask_features[k], dtype=np.float32).reshape(-1) for k in keys])
    hidden = [int(h) for h in ae_cfg.get("hidden", (256, 128, 64, 32))]
    epochs, lr = int(ae_cfg.get("epochs", 200)), float(ae_cfg.get("lr", 1e-3))
    cache = PriorCache(cache_dir)
    key = _fit_key(feats, latent_dim, hidden, epochs, lr, seed)
    hit = cache.load("autoencoder", key)
    if hit is not None:
        restored = _restore(hit, feats.shape[1], latent_dim, hidden)
        if restored is not None:
            log.info("autoencoder: the fit restored from %s", cache.entry("autoencoder", key))
            return restored
        log.warning("autoencoder: the cache entry %s does not hold this fit; replacing it with a new fit",
                    cache.entry("autoencoder", key))
        shutil.rmtree(cache.entry("autoencoder", key), ignore_errors=True)
    ae, stats = train_autoencoder(feats, latent_dim, hidden, epochs, lr, seed)
    if all(np.isfinite(v) for v in stats.values()):    # a diverged fit is not kept (JSON has no NaN)
        cache.save("autoencoder", key, {k: v.detach().cpu().numpy() for k, v in ae.state_dict().items()},
                   {"stats": stats})
    return ae, stats


def _restore(hit: tuple, in_dim: int, latent_dim: int, hidden: list[int]) -> Optional[tuple[FeatureAutoencoder, dict]]:
    """The frozen autoencoder and fit statistics of a cache entry, or None when the entry does not hold them."""
    arrays, meta = hit
    with torch.random.fork_rng(devices=[]):     # as the fit: the global generator is not drawn from
        ae = FeatureAutoencoder(in_dim, latent_dim, hidden)
    try:
        ae.load_state_dict({k: torch.from_numpy(v) for k, v in arrays.items()})
        stats = dict(meta["stats"])
    except (RuntimeError, KeyError, TypeError):
        return None
    ae.eval()
    for p in ae.parameters():
        p.requires_grad_(False)
    return ae, stats


def _fit_key(feats: np.ndarray, latent_dim: int, hidden: list[int], epochs: int, lr: float, seed: int) -> str:
    """The cache key of one fit: everything its bits depend on (the CPU's flags pick the BLAS kernels)."""
    content = {"features": hashlib.sha256(np.ascontiguousarray(feats).tobytes()).hexdigest(),
               "shape": list(feats.shape), "torch": torch.__version__, "cpu_flags": cpu_facts()["cpu_flags"]}
    params = {"latent_dim": int(latent_dim), "hidden": hidden, "epochs": epochs, "lr": lr, "seed": int(seed)}
    return cache_key("autoencoder", None, AE_CACHE_VERSION, params, content)


def semantic_targets(masks: dict, mask_features: dict, ae_cfg: dict, latent_dim: int, seed: int,
                     ae_state: dict | None, sizes: dict[int, tuple[int, int]], device: torch.device | str,
                     on: str, cache_dir: Optional[Path] = None) -> tuple[FeatureAutoencoder, dict, SemanticTargets]:
    """The autoencoder fitted on the mask features (or restored from `ae_state` on resume; the fit from
    `cache_dir` when an equal one is there), moved to `device`, and the per-view latent targets it encodes:
    what GaussianDS and twostage both start from."""
    ae, stats = fit_autoencoder(mask_features, ae_cfg, latent_dim, seed, cache_dir)
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
