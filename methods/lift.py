"""`lift`: a training-free lifting baseline (the family of Occam's LGS and Dr. Splat).

Stage 1 (`rgb`): RGB-only 3DGS, as `vanilla` (the harness runs the steps). Stage 2 is no optimisation:
with geometry and colour frozen, each Gaussian g gets the blending-weighted mean of the per-view
features of the pixels it contributes to,

    F_g = sum_v sum_p w_{g,p} f_p / sum_v sum_p w_{g,p}

over the training views v and their pixels p that carry a feature. f_p is the feature prior the
semantic methods train from (gsbench/priors/): the 512-d feature of the per-frame mask covering p
(as twostage's targets; a pixel outside every mask, or in a mask without a feature, carries none).
w_{g,p} = alpha_g(p) T_g(p) is g's blending weight at p in the render of the trained field. A Gaussian
that no feature-carrying pixel blends (sum of weights <= WEIGHT_FLOOR) gets the zero vector: it has no
direction, so it selects no query and gets no 3D class. F_g is the weighted mean, not renormalised.

How the weights are found (`weights_by_backward`, `weights_top_k`): the features are piecewise
constant per mask, so per view it suffices to know, for every Gaussian and mask k,
A_{g,k} = sum_{p in k} w_{g,p}. With `lift.top_k`
null they come from the renderer's own backward pass: render per-Gaussian channels c (N, K) = 0 with
the run's backend and take the gradient of sum_p sum_k [p in k] rendered_k(p); since rendered(p) =
sum_g w_{g,p} c_g, that gradient is exactly A. With `lift.top_k` = k only each pixel's k largest
weights count (Dr. Splat's top-k Gaussians per ray): the per-pixel weights come from the torch
reference rasterizer's compositing step (`_composite_chunk`, identity channels, the same tiles and
depth order), a running top-k per pixel is kept, and A is summed from it.

Queries: both modes answer in the 512-d feature space (no autoencoder): a pixel's feature is the
rendered F (alpha-blended like colour), the text is the feature provider's unit text embedding.
"""
from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Optional

import numpy as np
import torch

from gsbench.camera import Camera
from gsbench.config import setting
from gsbench.gaussians import GaussianField
from gsbench.methods.base import Method, Phases, _check_mode, fit_priors
from gsbench.methods.lift_spec import budget
from gsbench.methods.registry import uses
from gsbench.methods.vanilla import rgb_loss_fn
from gsbench.render import render, rules
from gsbench.render.projection import project_gaussians
from gsbench.render.torch_backend import CHUNK, _composite_chunk
from gsbench.train.feature_blocks import BLOCK_ROWS, FeatureBlocks
from gsbench.train.initial_field import scene_init
from gsbench.train.trainer import make_trainer
from gsbench.train.views import load_views

log = logging.getLogger(__name__)
WEIGHT_FLOOR = 1e-12   # a Gaussian whose summed weight is at or below this gets the zero feature


# ---------------------------------------------------------------------------- per-view weights
def mask_channels(mask: np.ndarray, view: int, mask_features: dict) -> tuple[list[int], np.ndarray]:
    """(ids, (H, W) int64 index into ids, -1 where the pixel carries no feature) of one view's mask:
    the track ids of the mask that have a feature for this view, in increasing order."""
    m = np.asarray(mask, dtype=np.int64)
    ids = [int(t) for t in np.unique(m) if t >= 0 and (view, int(t)) in mask_features]
    index = np.full(m.shape, -1, dtype=np.int64)
    for j, t in enumerate(ids):
        index[m == t] = j
    return ids, index


def weights_by_backward(field: GaussianField, camera: Camera, index: torch.Tensor, k: int,
                        backend: str) -> torch.Tensor:
    """(N, k) A[g, j] = sum of g's blending weights over the pixels with index == j (index: (H, W),
    -1 = none), from the backend's backward: d/dc of sum_p c-render_{index(p)}(p) with c = 0."""
    geom = field.detach()
    c = torch.zeros(geom.num, k, dtype=geom.means.dtype, device=geom.means.device, requires_grad=True)
    with torch.enable_grad():
        out = render(geom.with_features(c), camera, backend=backend)
        target = torch.zeros(index.shape[0], index.shape[1], k, dtype=c.dtype, device=c.device)
        rows = torch.nonzero(index >= 0)
        target[rows[:, 0], rows[:, 1], index[rows[:, 0], rows[:, 1]]] = 1.0
        (out.features * target).sum().backward()
    return c.grad.detach()


def _merge_top(best_w: torch.Tensor, best_i: torch.Tensor, w: torch.Tensor, ids: torch.Tensor,
               k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Keep each pixel's k largest weights among the kept ones and a chunk's (P, c) weights of Gaussians `ids`."""
    cand_w = torch.cat([best_w, w], dim=1)
    cand_i = torch.cat([best_i, ids.reshape(1, -1).expand(w.shape[0], -1)], dim=1)
    top = cand_w.topk(min(k, cand_w.shape[1]), dim=1)
    return top.values, torch.gather(cand_i, 1, top.indices)


def pixel_top_k(field: GaussianField, camera: Camera, k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """((H*W, k) weights, (H*W, k) Gaussian indices) of every pixel's k largest blending weights, from
    the torch reference rasterizer's tiles, depth order and compositing step; unused slots hold weight 0
    and index -1. Row-major pixels."""
    width, height = camera.width, camera.height
    with torch.no_grad():
        proj = project_gaussians(field.detach(), camera)
        dev, dt = proj.depths.device, proj.depths.dtype
        best_w = torch.zeros(height * width, k, dtype=dt, device=dev)
        best_i = torch.full((height * width, k), -1, dtype=torch.long, device=dev)
        means2d = proj.means2d[proj.ids]
        order = torch.sort(proj.depths, stable=True).indices
        radii = proj.radii[proj.ids][order].to(dt)
        md = means2d[order]
        x0, x1 = md[:, 0] - radii[:, 0], md[:, 0] + radii[:, 0]
        y0, y1 = md[:, 1] - radii[:, 1], md[:, 1] + radii[:, 1]
        ts = rules.TILE_SIZE
        for ya in range(0, height, ts):
            yb = min(height, ya + ts)
            for xa in range(0, width, ts):
                xb = min(width, xa + ts)
                sel = order[(y1 >= ya) & (y0 <= yb) & (x1 >= xa) & (x0 <= xb)]   # depth order
                if sel.numel() == 0:
                    continue
                ys, xs = torch.meshgrid(torch.arange(ya, yb, device=dev), torch.arange(xa, xb, device=dev),
                                        indexing="ij")
                pix = (ys * width + xs).reshape(-1)
                px, py = xs.reshape(-1).to(dt) + 0.5, ys.reshape(-1).to(dt) + 0.5
                t = torch.ones(pix.numel(), dtype=dt, device=dev)
                done = torch.zeros(pix.numel(), dtype=torch.bool, device=dev)
                bw, bi = best_w[pix], best_i[pix]
                for s in range(0, sel.numel(), CHUNK):
                    idx = sel[s:s + CHUNK]
                    eye = torch.eye(idx.numel(), dtype=dt, device=dev)
                    w, t, done = _composite_chunk(px, py, t, done, means2d[idx], proj.conics[idx],
                                                  proj.opacities[idx], eye)
                    bw, bi = _merge_top(bw, bi, w, proj.ids[idx], k)
                    if bool(done.all()):
                        break
                best_w[pix], best_i[pix] = bw, torch.where(bw > 0, bi, torch.full_like(bi, -1))
    return best_w, best_i


def weights_top_k(field: GaussianField, camera: Camera, index: torch.Tensor, k: int, top_k: int) -> torch.Tensor:
    """(N, k) A[g, j] = sum of g's weights over the pixels with index == j where g is among the pixel's
    `top_k` largest weights."""
    w, gid = pixel_top_k(field, camera, top_k)
    idx = index.reshape(-1, 1).expand_as(gid)
    keep = (gid >= 0) & (idx >= 0) & (w > 0)
    out = torch.zeros(field.num, k, dtype=w.dtype, device=w.device)
    out.index_put_((gid[keep], idx[keep]), w[keep], accumulate=True)
    return out


def lift_features(field: GaussianField, cameras: dict[int, Camera], masks: dict, mask_features: dict,
                  backend: str, top_k: Optional[int] = None) -> tuple[torch.Tensor, dict]:
    """((N, D) lifted features, stats) of a trained field from the views' masks and mask features
    (module docstring). `cameras`: view id -> camera at the masks' resolution."""
    dev, dt = field.means.device, field.means.dtype
    dim = len(next(iter(mask_features.values())))
    num = torch.zeros(field.num, dim, dtype=torch.float64, device=dev)
    den = torch.zeros(field.num, dtype=torch.float64, device=dev)
    for v in sorted(cameras):
        if v not in masks:
            continue
        cam = cameras[v]
        m = np.asarray(masks[v])
        if m.shape != (cam.height, cam.width):
            raise ValueError(f"mask of view {v} has shape {m.shape}, expected {(cam.height, cam.width)}")
        ids, index = mask_channels(m, v, mask_features)
        if not ids:
            continue
        index_t = torch.as_tensor(index, device=dev)
        if top_k is None:
            a = weights_by_backward(field, cam, index_t, len(ids), backend)
        else:
            a = weights_top_k(field, cam, index_t, len(ids), int(top_k))
        feats = torch.as_tensor(np.stack([np.asarray(mask_features[(v, t)], dtype=np.float64).reshape(-1)
                                          for t in ids]), device=dev)
        num += a.to(torch.float64) @ feats
        den += a.to(torch.float64).sum(dim=1)
    seen = den > WEIGHT_FLOOR
    out = torch.zeros_like(num)
    out[seen] = num[seen] / den[seen].unsqueeze(1)
    stats = {"lifted_gaussians": int(seen.sum()), "unseen_gaussians": int((~seen).sum()),
             "top_k": top_k, "weights": "backward" if top_k is None else "reference-rasterizer top-k"}
    return out.to(dt), stats


# ---------------------------------------------------------------------------- the method
class Lift(Method):
    name = "lift"

    @property
    def has_semantics(self) -> bool:
        return self.field is not None and self.field.features is not None

    def semantic_feature_blocks(self, camera: Camera, modes: tuple) -> dict:
        """{mode: FeatureBlocks of the rendered (H, W, 512) lifted features}, the same for both modes."""
        for m in modes:
            _check_mode(m)
        if not self.has_semantics:
            return {m: None for m in modes}
        blocks = FeatureBlocks.of_map(self.render(camera).features, None, rows=BLOCK_ROWS)
        return {m: blocks for m in modes}

    def gaussian_semantic_features(self, mode: str = "encode") -> Optional[torch.Tensor]:
        """(N, 512) the lifted per-Gaussian features (both modes: the text space)."""
        _check_mode(mode)
        return self.field.features if self.has_semantics else None

    def embed_text(self, texts: list[str], mode: str = "encode") -> Optional[torch.Tensor]:
        """(Q, 512) unit text embeddings of the feature provider (both modes)."""
        return self._unit_provider_text(texts, mode)

    def train_phases(self, scene, run_dir: Path, config: dict, resume: Optional[dict] = None,
                     progress: bool = True) -> Phases:
        run_dir = Path(run_dir)
        dev = self._prepare(config)
        views, _ = load_views(scene, config, device=dev)
        field0, how = scene_init(scene, config, 0)
        self.info["init"] = how
        rgb_field = yield make_trainer(config, views, scene, field0, run_dir,
                                       rgb_loss_fn(float(setting(config, "train.lambda_dssim"))),
                                       phase="rgb", backend=self._backend)
        self.info["device"] = str(dev)
        self.info["budget"] = budget(config)
        self.field = rgb_field
        self.info["n_gaussians"] = rgb_field.num
        if not uses(config)["semantics"]:
            return
        pri = fit_priors(scene, config, run_dir, progress=progress)
        self.providers = dict(pri.providers)
        self.info["priors_stats"] = dict(pri.stats)
        if pri.masks is None or not pri.mask_features:
            raise ValueError(f"lift: the priors gave no masks/features ({pri.skipped})")
        top_k = setting(config, "lift.top_k")
        t0 = time.perf_counter()
        feats, stats = lift_features(rgb_field, views.cameras, pri.masks, pri.mask_features, self._backend,
                                     None if top_k is None else int(top_k))
        self.field = rgb_field.with_features(feats)
        self.info["lift"] = dict(stats, lift_s=round(time.perf_counter() - t0, 3))
        log.info("lift: features lifted onto %d of %d Gaussians", stats["lifted_gaussians"], rgb_field.num)
