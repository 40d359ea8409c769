"""The shared 3DGS optimisation of every method: one phase's state and its step (`Trainer`). The loop
around the steps (schedule, logging, periodic evaluation, checkpoints, resume) is the harness's,
gsbench/runs/training.py.

Recipe (3DGS, every number a config value under `train`): Adam with one group per tensor
(position LR times the scene extent with exponential decay; colour, opacity, scaling, rotation,
semantic LRs), L_rec = (1 - lambda) L1 + lambda (1 - SSIM), adaptive density control (clone /
split / prune, opacity reset: gsbench/train/strategy.py's `DefaultStrategy`, which a method may replace),
initialisation from the scene's sparse points or uniformly at random in a cube around the cameras'
centroid (gsbench/train/initial_field.py).

The method supplies its loss as `loss_fn(ctx: StepContext) -> LossResult`: the context holds the step,
the view id, the render, the ground-truth image and the trainer (its parameters, for a loss on the
Gaussians themselves).
Runs are seeded (view order, split sampling, init) and resumable: `Trainer.state()` (written by the
harness to `checkpoint.pt`) holds parameters, Adam state, densification statistics, RNG states, step
and elapsed time. A non-finite loss or parameter raises NonFiniteError; the last good checkpoint is kept.

Device: the field, Adam state, densification statistics and background live on the device of the
views' images (gsbench.device.resolve_device). A step does no host work: loss terms, skip counts
and a first-non-finite-step flag stay on the device and are read only at log, eval, checkpoint and
densification steps (the loop's only synchronisation points), so a non-finite loss is reported
with its exact step at the next such point and no checkpoint is ever written after it. (This is
gsbench's code; gsplat 1.5.3 itself reads its tile-intersection count back once per render.)
SH colours (N, K, 3) are trained as two Adam groups, the DC band (`train.lr.color`) and the rest
(`colors_rest`, times `train.lr.color_rest_factor`), with one band more every
`train.sh_increase_every` steps (3DGS).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

import numpy as np
import torch

from gsbench import rundir
from gsbench.config import setting
from gsbench.errors import InputError, NonFiniteError
from gsbench.gaussians import GaussianField
from gsbench.render import RenderOutput, render
from gsbench.render.threads import torch_ops_serial
from gsbench.step_timers import timed
from gsbench.store import load_torch
from gsbench.train.adam import Adam
from gsbench.train.densify import ParamSet, expon_lr
from gsbench.train.strategy import Strategy, default_strategy
from gsbench.train.views import TrainViews

LR_KEYS = {"colors": "color", "opacity_logits": "opacity", "log_scales": "scaling", "quats": "rotation",
           "features": "semantic"}
SH_REST = "colors_rest"     # SH bands 1..3 as their own Adam group (3DGS: 1/20 of the base colour LR)


@dataclass
class LossResult:
    total: torch.Tensor
    terms: dict[str, torch.Tensor | float] = field(default_factory=dict)     # logged values (unweighted terms)
    skipped: dict[str, torch.Tensor | int] = field(default_factory=dict)     # counted skips, e.g. {"depth": 1}
    weighted: dict[str, torch.Tensor | float] = field(default_factory=dict)  # lambda * term: logged as loss_share
    # Values may be device tensors: the trainer sums them on the device and reads them at log steps only.

    def add(self, name: str, weight: float, term: torch.Tensor) -> None:
        """Add `weight * term` to the total, logging the term and its weighted value under `name`."""
        w = float(weight) * term
        self.total = self.total + w
        self.terms[name], self.weighted[name] = term.detach(), w.detach()


@dataclass(frozen=True)
class StepContext:
    """What a method's loss is given each step: the phase's step (1-based, already counted: the first
    step is 1), the view rendered, its render output and ground-truth image, and the trainer (read-only
    use: `params`, its field's tensors as optimised, e.g. for a regulariser on the Gaussians)."""

    step: int
    view_id: int
    out: RenderOutput
    gt: torch.Tensor                  # (H, W, 3) float in [0, 1]
    trainer: "Trainer"

    @property
    def params(self) -> dict[str, torch.nn.Parameter]:
        """The trainable tensors by field attribute name (`means`, `features`, ...), as the step renders them."""
        return self.trainer.ps.params


LossFn = Callable[[StepContext], LossResult]


@dataclass
class StepResult:
    """What one step gives the harness's loop to log: the method's loss terms, densification info
    (non-empty on a densify / prune / opacity-reset step) and the position learning rate."""

    loss: LossResult
    densify: dict
    lr_position: float


def field_from_params(ps: ParamSet | dict, sh_active: Optional[int] = None) -> GaussianField:
    """The field of a parameter set (or a checkpoint's `params`); SH bands stored as colours (N,1,3) plus
    `colors_rest`; `sh_active` keeps only the bands of that degree (3DGS's one band more per interval)."""
    p = ps.params if isinstance(ps, ParamSet) else ps
    colors = p["colors"]
    if SH_REST in p:
        colors = torch.cat([colors, p[SH_REST]], 1)
    if sh_active is not None and colors.dim() == 3:
        colors = colors[:, :(int(sh_active) + 1) ** 2]
    return GaussianField(p["means"], p["log_scales"], p["quats"], p["opacity_logits"], colors, p.get("features"))


def sh_active_degree(step: int, max_degree: int, every: int) -> int:
    """3DGS schedule: degree 0 first, one band more every `every` steps (0 = all bands from the start)."""
    if every <= 0:
        return max_degree
    return min(max_degree, max(0, int(step)) // int(every))


# ---------------------------------------------------------------------------- trainer
class Trainer:
    """One optimisation phase (e.g. `main`, or twostage's `rgb` / `semantic`)."""

    def __init__(self, cfg: dict, views: TrainViews, extent: float, field: GaussianField, run_dir: Path,
                 loss_fn: LossFn, *, phase: str = "main",
                 iterations: Optional[int] = None, trainable: Optional[set[str]] = None, densify: bool = True,
                 backend: str = "torch", seed: int = 0, extra_state: Optional[Callable[[], dict]] = None,
                 device: Optional[torch.device] = None,
                 extra_optimizer: Optional[Adam] = None, strategy: Optional[Strategy] = None) -> None:
        self.cfg = cfg
        self.views = views
        self.extent = float(extent) if extent and extent > 0 else 1.0
        self.run_dir = Path(run_dir)
        self.loss_fn = loss_fn
        self.phase = phase
        self.iterations = int(setting(cfg, "train.iterations") if iterations is None else iterations)
        # densification: the method's own strategy, or 3DGS's (on when `densify` and train.densify.enabled)
        self.strategy = strategy if strategy is not None else default_strategy(cfg, densify)
        self.backend = backend
        self.seed = int(seed)
        self.extra_state = extra_state
        # a method's own module trained with the field (e.g. grouping's identity classifier): stepped
        # right after the field's Adam, from the same backward pass; its state travels in extra_state
        self.extra_optimizer = extra_optimizer
        self.device = torch.device(device) if device is not None else field.means.device
        # the position LR schedule (3DGS's expon_lr), read once: _update_lr applies it every step
        self._position_lr = (setting(cfg, "train.lr.position_init") * self.extent,
                            setting(cfg, "train.lr.position_final") * self.extent,
                            int(setting(cfg, "train.lr.position_max_steps")),
                            int(setting(cfg, "train.lr.position_delay_steps") or 0),
                            float(setting(cfg, "train.lr.position_delay_mult")))
        lrs = {"means": self._position_lr[0]}
        for k, key in LR_KEYS.items():
            lrs[k] = setting(cfg, f"train.lr.{key}")
        lrs[SH_REST] = float(setting(cfg, "train.lr.color")) * float(setting(cfg, "train.lr.color_rest_factor"))
        tensors = {k: v.to(self.device) for k, v in field.tensors().items() if v is not None}
        self.sh_max = field.sh_degree or 0
        self.sh_every = int(setting(cfg, "train.sh_increase_every") or 0)
        if self.sh_max > 0:
            c = tensors.pop("colors")
            tensors["colors"], tensors[SH_REST] = c[:, :1].contiguous(), c[:, 1:].contiguous()
        if trainable is not None and "colors" in trainable:
            trainable = set(trainable) | {SH_REST}
        self.ps = ParamSet(tensors, lrs, trainable)
        self.step = 0
        self.elapsed = 0.0
        self.view_rng = np.random.default_rng(self.seed)
        self.view_stack: list[int] = []
        self.torch_gen = torch.Generator(device=self.device).manual_seed(self.seed + 1)
        bg = setting(self.cfg, "train.background")
        self.background = torch.tensor(bg, dtype=torch.float32, device=self.device)
        self.bad_step = torch.zeros((), dtype=torch.long, device=self.device)   # first step with a non-finite loss
        self.strategy.initialize(self)

    # ------------------------------------------------------------------ state
    @property
    def field(self) -> GaussianField:
        return field_from_params(self.ps).detach()

    def state(self) -> dict:
        return {"phase": self.phase, "step": self.step, "elapsed_s": self.elapsed,
                "params": {k: v.data.cpu() for k, v in self.ps.params.items()},
                "optimizer": self.ps.optimizer.state_dict(), "densify": self.strategy.state_dict(),
                "view_rng": self.view_rng.bit_generator.state, "view_stack": list(self.view_stack),
                "torch_gen": self.torch_gen.get_state(), "torch_rng": torch.get_rng_state(),
                "device": str(self.device), "backend": self.backend,
                "extra": self.extra_state() if self.extra_state else {}}

    def _check_resumable(self, st: dict) -> None:
        """A checkpoint resumes only on the device kind and render backend that wrote it: the split
        generator's state is device-specific (5,056 bytes on the CPU, 16 on CUDA), and a run half
        rendered by one backend and half by another would be recorded as the second's. A grid started
        on one kind of machine and resumed on the other gets this error for its cell, not a crash."""
        dev, backend = st.get("device"), st.get("backend")
        gen = st.get("torch_gen")
        own = self.torch_gen.get_state()
        size_differs = torch.is_tensor(gen) and gen.numel() != own.numel()   # checkpoints without "device"
        if ((dev is not None and torch.device(dev).type != self.device.type) or size_differs
                or (backend is not None and backend != self.backend)):
            was = f"{dev or 'another kind of device'}" + (f" with backend {backend}" if backend else "")
            raise InputError(f"{self.run_dir / rundir.CHECKPOINT}: written training on {was}; this run resolves to "
                             f"{self.device} with backend {self.backend} here. Resume it on the kind of machine that "
                             f"started it, or delete the checkpoint to train this run from step 0")

    def load_state(self, st: dict) -> None:
        if st.get("phase") != self.phase:
            raise ValueError(f"checkpoint phase {st.get('phase')!r} != {self.phase!r}")
        self._check_resumable(st)
        lrs = {g["name"]: g["lr"] for g in self.ps.optimizer.param_groups}
        trainable = {g["name"] for g in self.ps.optimizer.param_groups}
        self.ps = ParamSet({k: v.to(self.device) for k, v in st["params"].items()},
                           {k: lrs.get(k, 0.0) for k in st["params"]}, trainable)
        self.ps.optimizer.load_state_dict(st["optimizer"])
        self.strategy.load_state_dict(st["densify"])
        self.step = int(st["step"])
        self.elapsed = float(st["elapsed_s"])
        self.view_rng.bit_generator.state = st["view_rng"]
        self.view_stack = list(st["view_stack"])
        self.torch_gen.set_state(st["torch_gen"].cpu() if torch.is_tensor(st["torch_gen"]) else st["torch_gen"])
        torch.set_rng_state(st["torch_rng"])

    # ------------------------------------------------------------------ schedule
    def _next_view(self) -> int:
        if not self.view_stack:
            ids = sorted(self.views.cameras)
            self.view_stack = [int(i) for i in self.view_rng.permutation(ids)]
        return self.view_stack.pop()

    def _update_lr(self) -> float:
        v = expon_lr(self.step, *self._position_lr)
        g = self.ps.group("means")
        if g is not None:
            g["lr"] = v
        return v

    def _kept(self) -> str:
        ck = self.run_dir / rundir.CHECKPOINT
        return (f"the last good checkpoint is kept in {ck}" if ck.exists()
                else "no checkpoint was written before this step")

    def check_finite(self, what: str, value: torch.Tensor | None = None) -> None:
        if value is not None:
            if not bool(torch.isfinite(value).all()):
                raise NonFiniteError(f"non-finite {what} at step {self.step} (phase {self.phase}); "
                                     f"{self._kept()}")
            return
        for k, p in self.ps.params.items():
            if not bool(torch.isfinite(p.data).all()):
                raise NonFiniteError(f"non-finite parameter {k!r} at step {self.step} (phase {self.phase}); "
                                     f"{self._kept()}")

    def synchronize(self) -> None:
        if self.device.type == "cuda":
            torch.cuda.synchronize(self.device)

    def raise_if_bad(self) -> None:
        """Non-finite losses are flagged on the device each step and raised here (log, eval, checkpoint
        and densification steps), with the first bad step; no checkpoint is written after it."""
        b = int(self.bad_step)
        if b > 0:
            raise NonFiniteError(f"non-finite loss at step {b} (phase {self.phase}); {self._kept()}")

    def sh_degree(self) -> int:
        """The SH degree the last step rendered with (one band more every `train.sh_increase_every`)."""
        return sh_active_degree(self.step - 1, self.sh_max, self.sh_every)

    # ------------------------------------------------------------------ one step
    def train_iteration(self) -> StepResult:
        """One optimisation step (the harness, gsbench.runs.training, owns the loop around it): the next view,
        render, the method's loss (given a `StepContext`), backward, the strategy's statistics, Adam, and
        the strategy's densify / prune / opacity reset on its schedule. Values stay on the device; a
        non-finite loss is flagged in `bad_step` and raised by `raise_if_bad` at the loop's next
        synchronisation point. On the CPU the step's PyTorch ops run on one thread and the render kernels
        on all (gsbench.render.threads): faster, and the same bits for any thread count."""
        if self.device.type != "cpu":
            return self._iteration()
        with torch_ops_serial():
            return self._iteration()

    def _iteration(self) -> StepResult:
        self.step += 1
        lr_pos = self._update_lr()
        vid = self._next_view()
        cam = self.views.cameras[vid]
        gt = self.views.images[vid]
        fld = field_from_params(self.ps, sh_active_degree(self.step - 1, self.sh_max, self.sh_every))
        out = render(fld, cam, backend=self.backend, background=self.background)
        with timed("losses"):
            res = self.loss_fn(StepContext(self.step, vid, out, gt, self))
        tot = res.total.detach()
        self.bad_step = torch.where((self.bad_step == 0) & ~torch.isfinite(tot),
                                    torch.full_like(self.bad_step, self.step), self.bad_step)
        self.ps.optimizer.zero_grad(set_to_none=True)
        if self.extra_optimizer is not None:
            self.extra_optimizer.zero_grad(set_to_none=True)
        with timed("backward"):
            res.total.backward()
        with torch.no_grad():
            self.strategy.step_post_backward(self, out, cam)
            try:
                with timed("optimiser"):
                    self.ps.optimizer.step()
                    if self.extra_optimizer is not None:
                        self.extra_optimizer.step()
            except RuntimeError as e:   # e.g. Adam's lr / (1 - beta1) overflows float32 (lr ~1e38)
                if "overflow" not in str(e):
                    raise
                raise NonFiniteError(f"optimiser step overflowed at step {self.step} (phase {self.phase}): {e}; "
                                     f"{self._kept()}") from None
            info = self.strategy.step_post_optimizer(self)
        return StepResult(res, info, lr_pos)


def make_trainer(config: dict, views: TrainViews, scene, field0: GaussianField, run_dir: Path,
                 loss_fn: LossFn, *, phase: str, backend: str, iterations: Optional[int] = None,
                 trainable: Optional[set] = None, densify: bool = True,
                 extra_state: Optional[Callable[[], dict]] = None, extra_optimizer: Optional[Adam] = None,
                 strategy: Optional[Strategy] = None) -> Trainer:
    """One optimisation phase with the shared 3DGS recipe and the method's loss, on the views' device:
    what a method yields to the harness's loop (gsbench.runs.training) from `train_phases`.

    `trainable`: the field tensors optimised (None: all); `densify=False` or a `strategy` of the method's
    own replaces 3DGS's density control (gsbench/train/strategy.py); `extra_optimizer` steps a module of
    the method's own from the same backward pass (its state belongs in `extra_state`, which the
    checkpoint holds as `extra`)."""
    dev = next(iter(views.images.values())).device if views.images else torch.device("cpu")
    return Trainer(config, views, float(scene.extent or 1.0), field0, run_dir, loss_fn, phase=phase,
                   iterations=iterations, trainable=trainable, densify=densify, backend=backend,
                   seed=int(setting(config, "seed")), extra_state=extra_state, device=dev,
                   extra_optimizer=extra_optimizer, strategy=strategy)


def load_checkpoint_if_any(run_dir: Path) -> Optional[dict]:
    p = Path(run_dir) / rundir.CHECKPOINT
    return load_torch(p) if p.exists() else None


__all__ = ["Trainer", "LossResult", "LossFn", "StepContext", "StepResult", "make_trainer", "load_checkpoint_if_any"]
