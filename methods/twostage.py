"""`twostage`: the decoupled paradigm the paper argues against.

Stage 1 (`rgb`): RGB-only 3DGS (as `vanilla`, `train.iterations`). Stage 2 (`semantic`): geometry and
colour frozen, no densification; only the per-Gaussian latents are optimised with L_sem for
`twostage.semantic_iterations` (null = train.iterations, GaussianDS's semantic budget), from per-frame
(unpropagated) masks: ids are not consistent across views, so each view's target comes from that view's
own mask features only.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import torch

from gsbench.config import setting
from gsbench.methods.base import Method, Phases, cache_dir_for, fit_priors
from gsbench.methods.registry import uses
from gsbench.methods.twostage_spec import budget, semantic_budget
from gsbench.methods.vanilla import rgb_loss_fn
from gsbench.train.initial_field import scene_init
from gsbench.train.losses import sem_loss
from gsbench.train.residency import data_on
from gsbench.train.semantic_targets import semantic_targets
from gsbench.train.trainer import LossResult, StepContext, field_from_params, make_trainer
from gsbench.train.views import load_views


class TwoStage(Method):
    name = "twostage"

    def train_phases(self, scene, run_dir: Path, config: dict, resume: Optional[dict] = None,
                     progress: bool = True) -> Phases:
        run_dir = Path(run_dir)
        ckpt = resume
        dev = self._prepare(config)
        views, (W, H) = load_views(scene, config, device=dev)
        sem_steps = semantic_budget(config)
        train_ids = sorted(views.cameras)
        # ---- stage 1: RGB
        field0, how = scene_init(scene, config, 0)
        self.info["init"] = how
        if ckpt is not None and ckpt.get("phase") == "semantic":
            rgb_field = None                      # stage 1 finished before the interruption
        else:
            rgb_field = yield make_trainer(config, views, scene, field0, run_dir,
                                           rgb_loss_fn(float(setting(config, "train.lambda_dssim"))),
                                           phase="rgb", backend=self._backend)
        self.info["device"] = str(dev)
        self.info["budget"] = budget(config)
        if not uses(config)["semantics"]:
            self.field = rgb_field
            self.info["n_gaussians"] = self.field.num
            return
        # ---- stage 2: semantics from per-frame masks on frozen geometry
        d = int(setting(config, "semantic.latent_dim"))
        pri = fit_priors(scene, config, run_dir, progress=progress)
        self.providers = dict(pri.providers)
        self.info["priors_stats"] = dict(pri.stats)
        if pri.masks is None or pri.mask_features is None:
            raise ValueError(f"twostage: the priors gave no masks/features ({pri.skipped})")
        ae_state = (ckpt or {}).get("extra", {}).get("autoencoder") if (ckpt or {}).get("phase") == "semantic" else None
        self.autoencoder, self.info["autoencoder"], targets = semantic_targets(
            pri.masks, pri.mask_features, setting(config, "semantic.autoencoder"), d, int(setting(config, "seed")),
            ae_state, {v: (W, H) for v in train_ids}, dev, data_on(config), cache_dir_for(config, run_dir))
        has_any = {v: bool(targets.has_target[v].any()) for v in train_ids}
        if rgb_field is None:
            sem_field0 = field_from_params(ckpt["params"])
        else:
            sem_field0 = rgb_field.with_features(torch.zeros(rgb_field.num, d, device=rgb_field.means.device))

        def loss_fn(ctx: StepContext) -> LossResult:
            vid, out = ctx.view_id, ctx.out
            if not has_any[vid]:
                z = out.features.sum() * 0.0
                return LossResult(z, {"total": z.detach()}, {"sem": 1})
            ls = sem_loss(out.features, targets.latents[vid], targets.has_target[vid])
            v = ls.detach()
            return LossResult(ls, {"sem": v, "total": v}, weighted={"sem": v})

        self.field = yield make_trainer(config, views, scene, sem_field0, run_dir, loss_fn, phase="semantic",
                                        backend=self._backend, iterations=sem_steps, trainable={"features"},
                                        densify=False,
                                        extra_state=lambda: {"autoencoder": self.autoencoder.state_dict()})
        self.info["n_gaussians"] = self.field.num
