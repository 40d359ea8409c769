"""`vanilla`: RGB-only 3DGS (the paper's "3DGS" column): L_rec only, the shared trainer's recipe."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

from gsbench.config import setting
from gsbench.methods.base import Method, Phases
from gsbench.methods.vanilla_spec import budget
from gsbench.train.initial_field import scene_init
from gsbench.train.losses import reconstruction_loss
from gsbench.train.trainer import LossFn, LossResult, StepContext, make_trainer
from gsbench.train.views import load_views


def rgb_loss_fn(lam_dssim: float) -> LossFn:
    def loss_fn(ctx: StepContext) -> LossResult:
        rec = reconstruction_loss(ctx.out.rgb, ctx.gt, lam_dssim)
        v = rec.detach()
        return LossResult(rec, {"rec": v, "total": v}, weighted={"rec": v})
    return loss_fn


class Vanilla(Method):
    name = "vanilla"

    def train_phases(self, scene, run_dir: Path, config: dict, resume: Optional[dict] = None,
                     progress: bool = True) -> Phases:
        dev = self._prepare(config)
        views, _ = load_views(scene, config, device=dev)
        field0, how = scene_init(scene, config, 0)
        self.info["init"] = how
        self.field = yield make_trainer(config, views, scene, field0, Path(run_dir),
                                        rgb_loss_fn(float(setting(config, "train.lambda_dssim"))),
                                        phase="main", backend=self._backend)
        self.info["n_gaussians"] = self.field.num
        self.info["device"] = str(dev)
        self.info["budget"] = budget(config)
