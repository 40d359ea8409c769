"""Densification strategies: how a phase grows, shrinks and resets its Gaussians around the optimiser.

The step (`Trainer.train_iteration`) calls its strategy twice per step, and nothing else in the step
knows about densification:

    render -> the method's loss -> backward
        strategy.step_post_backward(trainer, out, camera)   # gradients are live: gather statistics
    optimiser step
        info = strategy.step_post_optimizer(trainer)        # change the Gaussians on the schedule

A strategy may read the trainer's `step`, `extent`, `device`, `ps` (the `ParamSet`: tensors and their
Adam; change rows only through `ps.append` / `ps.keep` / `ps.set_values`, which keep Adam's moments in
step) and `torch_gen` (the phase's seeded generator), and call `raise_if_bad()` before it acts on
values a non-finite loss may have touched. What `step_post_optimizer` returns is logged
(train_log.jsonl `densify`, and the step is a log step) when it is not empty. `state_dict` /
`load_state_dict` travel in the checkpoint (its `densify` entry), so a resumed run continues the
strategy where it stopped.

`DefaultStrategy` is 3DGS's adaptive density control (gsbench/train/densify.py); a method that wants
another rule passes its own object to `make_trainer(..., strategy=...)`. The idea follows gsplat's
`strategy` objects (a default and an MCMC strategy behind one small interface), in gsbench's terms.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from gsbench.camera import Camera
from gsbench.config import setting
from gsbench.render import RenderOutput
from gsbench.step_timers import timed
from gsbench.train.densify import DensifyStats, densify_and_prune, reset_opacity

if TYPE_CHECKING:   # the trainer imports this module; the hooks only receive a trainer
    from gsbench.train.trainer import Trainer


class Strategy(Protocol):
    """The interface of a densification strategy (module docstring)."""

    def initialize(self, tr: "Trainer") -> None:
        """Called once by the trainer, after its parameters exist (before any step or resume)."""

    def step_post_backward(self, tr: "Trainer", out: RenderOutput, camera: Camera) -> None:
        """After the loss's backward pass, before the optimiser step (gradients of `out` are live)."""

    def step_post_optimizer(self, tr: "Trainer") -> dict:
        """After the optimiser step: densify / prune / reset as the strategy decides; what to log."""

    def state_dict(self) -> dict:
        """The strategy's resumable state (checkpoint entry `densify`)."""

    def load_state_dict(self, st: dict) -> None:
        """Restore `state_dict()`'s result (resume), after the trainer restored its parameters."""


class DefaultStrategy:
    """3DGS's adaptive density control, every number from config `train.densify` (`cfg`): screen-space
    gradient statistics up to `until_iter`; clone / split / prune every `interval` steps after
    `from_iter` (large Gaussians pruned too once past the first opacity reset); opacities reset every
    `opacity_reset_interval` steps. `enabled=False` gathers nothing and changes nothing (a phase on
    frozen geometry, or `train.densify.enabled: false`), its statistics still saved for the checkpoint."""

    def __init__(self, cfg: dict, enabled: bool = True) -> None:
        self.cfg = cfg
        self.enabled = bool(enabled)
        self.stats: DensifyStats | None = None

    def initialize(self, tr: "Trainer") -> None:
        self.stats = DensifyStats(tr.ps.num, device=tr.device)

    def _active(self, step: int) -> bool:
        return self.enabled and step < int(self.cfg["until_iter"])

    def step_post_backward(self, tr: "Trainer", out: RenderOutput, camera: Camera) -> None:
        if self._active(tr.step) and out.radii is not None:
            with timed("densify"):
                self.stats.update(out.means2d.grad if out.means2d is not None else None, out.radii,
                                  camera.width, camera.height)

    def step_post_optimizer(self, tr: "Trainer") -> dict:
        d, step = self.cfg, tr.step
        info: dict = {}
        if not self._active(step):
            return info
        reset_every = int(d["opacity_reset_interval"])
        if step > int(d["from_iter"]) and step % int(d["interval"]) == 0:
            tr.raise_if_bad()      # never densify from non-finite values
            with timed("densify"):
                info = densify_and_prune(tr.ps, self.stats, d, tr.extent, prune_big=step > reset_every,
                                         generator=tr.torch_gen)
        if reset_every > 0 and step % reset_every == 0:
            with timed("densify"):
                reset_opacity(tr.ps)
            info["opacity_reset"] = True
        return info

    def state_dict(self) -> dict:
        return self.stats.state_dict()

    def load_state_dict(self, st: dict) -> None:
        self.stats.load_state_dict(st)


def default_strategy(config: dict, densify: bool = True) -> DefaultStrategy:
    """The strategy of a phase that names none: 3DGS's, on when `densify` and `train.densify.enabled`."""
    return DefaultStrategy(setting(config, "train.densify"),
                           enabled=bool(densify and setting(config, "train.densify.enabled")))


__all__ = ["Strategy", "DefaultStrategy", "default_strategy"]
