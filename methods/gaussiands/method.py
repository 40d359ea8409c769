"""GaussianDS: joint optimisation from scratch of appearance, scale-shift-aligned depth and compact
semantic latents (paper Sec. III-IV; the choices made where the paper is silent: docs/methods.md).

    L = L_rec + 0.01 L_depth + 1.5 L_tv + 5.0 L_sem + 1.0 L_ds      (config gaussiands.lambdas)

L_depth and L_tv see the rendered depth divided by its own (detached) alpha-weighted mean
(losses.normalised_depth), so both are scale-free and the lambdas weigh them alike on every scene.

Inputs come from gsbench.priors: pose-aware pseudo-video order (priors.ordering), propagated masks,
512-d mask features (compressed by the frozen autoencoder to d = semantic.latent_dim) and the depth
prior. Terms the resolved config switched off (gaussiands.losses.*, semantic.loss) are neither computed nor fed.
`gaussiands.sem_geometry` (null = joint) says whether L_sem and L_ds also move the geometry and the densification
statistic (docs/methods.md, "Where GaussianDS's PSNR goes at small d").
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Optional

import numpy as np
import torch

from gsbench.config import setting
from gsbench.gaussians import GaussianField
from gsbench.methods.base import Method, Phases, cache_dir_for, fit_priors
from gsbench.methods.gaussiands.spec import budget
from gsbench.methods.registry import uses
from gsbench.render import render
from gsbench.train.initial_field import scene_init
from gsbench.train.losses import (
    EDGE_FLOOR,
    depth_edges,
    depth_loss,
    ds_loss,
    edge_coverage,
    expected_depth,
    normalised_depth,
    reconstruction_loss,
    sem_loss,
    tv_loss,
)
from gsbench.train.residency import data_on, place
from gsbench.train.semantic_targets import semantic_targets
from gsbench.train.trainer import LossFn, LossResult, StepContext, make_trainer
from gsbench.train.views import load_views

log = logging.getLogger(__name__)


class GaussianDS(Method):
    name = "gaussiands"

    def train_phases(self, scene, run_dir: Path, config: dict, resume: Optional[dict] = None,
                     progress: bool = True) -> Phases:
        run_dir = Path(run_dir)
        dev = self._prepare(config)
        use = uses(config)
        # priors first: their working set (every image at the training size, flows) is freed before the
        # training images are loaded, so the peak is the larger of the two, not their sum
        pri = fit_priors(scene, config, run_dir, progress=progress)
        views, (W, H) = load_views(scene, config, device=dev)
        train_ids = sorted(views.cameras)
        self.providers = dict(pri.providers)
        self.info["priors_stats"] = dict(pri.stats)
        self.info["priors_skipped"] = dict(pri.skipped)

        targets = None
        d = int(setting(config, "semantic.latent_dim")) if use["semantics"] else 0
        if use["semantics"]:
            targets = self._semantic_targets(pri, config, d, resume, {v: (W, H) for v in train_ids}, dev,
                                             cache_dir_for(config, run_dir))
        # ---- depth prior and its edges E_d (invariant to the per-iteration affine alignment, see losses.py)
        depth = pri.depth if use["depth_prior"] else None
        edges = {}
        if use["depth_prior"] and depth is None:
            raise ValueError(f"gaussiands: depth terms are on but the priors gave no depth ({pri.skipped})")
        if setting(config, "gaussiands.losses.ds") and depth is not None:
            edges = self._depth_edges(depth, setting(config, "gaussiands.edges"), train_ids, dev, config)
        dprior = _device_depth_prior(depth, train_ids, dev, config)
        has_any = {v: bool(targets.has_target[v].any()) for v in train_ids} if targets is not None else {}
        # the host copies of the priors are no longer needed: the targets, dprior and edges hold what training
        # reads (at 1440x1080 the masks and depth maps of 175 views are about 2.5 GB)
        del pri, depth

        loss_fn = gaussiands_loss(config, dprior, targets, has_any, edges)
        extra = (lambda: {"autoencoder": self.autoencoder.state_dict()}) if self.autoencoder is not None else None
        field0, how = scene_init(scene, config, d)
        self.info["init"] = how
        self.field = yield make_trainer(config, views, scene, field0, run_dir, loss_fn, phase="main",
                                        backend=self._backend, extra_state=extra)
        self.info["n_gaussians"] = self.field.num
        self.info["device"] = str(dev)
        self.info["budget"] = budget(config)   # one joint phase: every step is appearance and semantics

    def _semantic_targets(self, pri, config: dict, d: int, resume: Optional[dict], sizes: dict, dev,
                          cache_dir: Path):
        """The autoencoder (trained once, frozen; restored from the checkpoint on resume) and the per-pixel
        latent targets it makes of the priors' masks and mask features."""
        if pri.masks is None or pri.mask_features is None:
            raise ValueError(f"gaussiands: semantic losses are on but the priors gave no masks/features "
                             f"({pri.skipped})")
        ae_state = (resume or {}).get("extra", {}).get("autoencoder")
        self.autoencoder, self.info["autoencoder"], targets = semantic_targets(
            pri.masks, pri.mask_features, setting(config, "semantic.autoencoder"), d, int(setting(config, "seed")),
            ae_state, sizes, dev, data_on(config), cache_dir)
        return targets

    def _depth_edges(self, depth: dict, e: dict, train_ids: list[int], dev, config: dict) -> dict:
        """The depth prior's edge map E_d per view (what L_ds acts on), placed for training; its coverage is
        recorded, and a map that covers almost nothing is warned about."""
        edges_np = {v: depth_edges(depth[v].values, depth[v].valid, e["canny_low"], e["canny_high"],
                                   int(e["dilate"]), e.get("size")) for v in train_ids}
        share, n_empty = edge_coverage(edges_np)
        self.info["edge_fraction"], self.info["edge_views_empty"] = share, n_empty
        if n_empty:
            # not an error (a smooth prior can have no edges), but never silent: L_ds then does nothing
            log.warning("L_ds: the depth-edge map E_d (Canny %s/%s on the depth prior) covers %.3f %% of the "
                        "pixels; %d of %d views are below %.1f %%, where L_ds acts on almost nothing "
                        "(docs/methods.md, 'When E_d is empty')", e["canny_low"], e["canny_high"], 100 * share,
                        n_empty, len(edges_np), 100 * EDGE_FLOOR)
        return place({v: torch.as_tensor(x) for v, x in edges_np.items()}, dev, data_on(config))


def _device_depth_prior(depth: Optional[dict], train_ids: list[int], dev, config: dict) -> dict:
    """The depth prior on the device once (or on the host: train.data_on), per view: values (float32, non-finite
    zeroed), validity (valid and finite), its kind. Empty without a depth prior."""
    dprior = {}
    if depth is not None:
        for v in train_ids:
            vals = torch.as_tensor(np.asarray(depth[v].values, dtype=np.float32))
            ok = torch.as_tensor(np.asarray(depth[v].valid, dtype=bool)) & torch.isfinite(vals)
            dprior[v] = (torch.nan_to_num(vals, nan=0.0, posinf=0.0, neginf=0.0), ok, depth[v].kind)
        dprior = place(dprior, dev, data_on(config))
    return dprior


def gaussiands_loss(config: dict, dprior: dict, targets, has_any: dict[int, bool],
                    edges: dict) -> LossFn:
    """The per-step loss L = L_rec + the switched-on weighted terms (module docstring), as the trainer calls
    it: StepContext (view id, render output, ground-truth image) -> LossResult."""
    # every setting read once here, not per step
    lam = {k: setting(config, f"gaussiands.lambdas.{k}") for k in ("depth", "tv", "sem", "ds")}
    on = {**setting(config, "gaussiands.losses"), "sem": bool(setting(config, "semantic.loss"))}   # L_sem: shared
    lam_dssim = float(setting(config, "train.lambda_dssim"))
    form = setting(config, "gaussiands.depth_formulation")
    min_valid = int(setting(config, "gaussiands.min_valid_pixels"))
    tv_eps = float(setting(config, "gaussiands.tv_eps"))
    ds_average = str(setting(config, "gaussiands.ds_average"))
    sem_geometry = setting(config, "gaussiands.sem_geometry") or "joint"

    def loss_fn(ctx: StepContext) -> LossResult:
        # every value stays on the device: no host synchronisation per step (the trainer reads
        # terms, weighted terms and skip counts at log steps only)
        vid, out = ctx.view_id, ctx.out
        rec = reconstruction_loss(out.rgb, ctx.gt, lam_dssim)
        res = LossResult(rec, {"rec": rec.detach()}, {}, {"rec": rec.detach()})
        if (on["depth"] and dprior) or on["tv"]:
            dn = normalised_depth(out.depth, out.alpha)     # scale-free: lambdas mean the same on every scene
        if on["depth"] and dprior:
            vals, valid, kind = dprior[vid]
            # the prior is compared with the depth of the covered part (D / alpha), never with D:
            # 1 / D confounds coverage with depth (losses.expected_depth)
            dt = depth_loss(form, expected_depth(dn, out.alpha), vals, valid, kind, min_valid)
            if dt.loss is not None:
                res.add("depth", lam["depth"], dt.loss)
                res.skipped["depth"] = (~dt.ok).long()
        if on["tv"]:
            res.add("tv", lam["tv"], tv_loss(dn, tv_eps))
        if targets is not None and out.features is not None:
            S, has = targets.latents[vid], targets.has_target[vid]
            feats = out.features
            if sem_geometry != "joint" and has_any[vid] and (on["sem"] or (on["ds"] and vid in edges)):
                feats = latent_render(ctx, detach_geometry=sem_geometry == "detached")
            if on["sem"]:
                if not has_any[vid]:
                    res.skipped["sem"] = 1
                else:
                    res.add("sem", lam["sem"], sem_loss(feats, S, has))
            if on["ds"] and vid in edges:
                if not has_any[vid]:
                    res.skipped["ds"] = 1
                else:
                    res.add("ds", lam["ds"], ds_loss(feats, S, has, edges[vid], ds_average))
        res.terms["total"] = res.total.detach()
        return res

    return loss_fn


def latent_render(ctx: StepContext, detach_geometry: bool) -> torch.Tensor:
    """The step's view rendered a second time for the semantic terms (`gaussiands.sem_geometry` other than
    joint): its screen positions are not the ones the densification statistic reads, so L_sem and L_ds no
    longer drive densification; with `detach_geometry` their gradient reaches the latents only (positions,
    scales, rotations and opacities are constants here). The colours are constants either way."""
    p, backend = ctx.params, ctx.trainer.backend
    keep = (lambda t: t.detach()) if detach_geometry else (lambda t: t)
    fld = GaussianField(keep(p["means"]), keep(p["log_scales"]), keep(p["quats"]), keep(p["opacity_logits"]),
                        p["colors"].detach(), p["features"])
    return render(fld, ctx.trainer.views.cameras[ctx.view_id], backend=backend).features
