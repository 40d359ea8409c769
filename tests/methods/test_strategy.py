"""The engine's two seams for a method (gsbench/train): the loss receives a `StepContext`, and
densification is a strategy object the method may replace (gsbench/train/strategy.py); plus the
method hook the loop's periodic evaluation uses for a mid-phase field (`Method.with_field`)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from render_fields import look_at

from gsbench.config import load_config
from gsbench.methods.base import Method
from gsbench.train.initial_field import init_field
from gsbench.train.losses import reconstruction_loss
from gsbench.train.strategy import DefaultStrategy
from gsbench.train.trainer import LossResult, StepContext, Trainer
from gsbench.train.views import TrainViews


class CountingStrategy:
    """A strategy of a method's own: no densification, every call recorded."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, int]] = []
        self.loaded = None

    def initialize(self, tr) -> None:
        self.calls.append(("initialize", tr.step))

    def step_post_backward(self, tr, out, camera) -> None:
        assert tr.ps.params["means"].grad is not None      # after backward, before Adam
        self.calls.append(("post_backward", tr.step))

    def step_post_optimizer(self, tr) -> dict:
        self.calls.append(("post_optimizer", tr.step))
        return {"counted": tr.step} if tr.step == 2 else {}

    def state_dict(self) -> dict:
        return {"n_calls": len(self.calls)}

    def load_state_dict(self, st: dict) -> None:
        self.loaded = st


def _trainer(tmp_path, loss_fn, **kw) -> Trainer:
    cfg = load_config("vanilla", "cpu-small", ["backend=torch"])
    cam = look_at(16, 12, (0.0, 0.0, -3.0))
    views = TrainViews({0: cam, 1: cam}, {0: torch.full((12, 16, 3), 0.5), 1: torch.full((12, 16, 3), 0.25)})
    fld, _ = init_field(None, None, "random", 32, np.zeros(3), 0.5, 0, 0, seed=0)
    return Trainer(cfg, views, 1.0, fld, tmp_path, loss_fn, backend="torch", **kw)


def _rgb_loss(ctx: StepContext) -> LossResult:
    rec = reconstruction_loss(ctx.out.rgb, ctx.gt, 0.2)
    return LossResult(rec, {"total": rec.detach()})


def test_the_loss_gets_a_frozen_context_of_the_step(tmp_path):
    seen = []

    def loss_fn(ctx: StepContext) -> LossResult:
        seen.append(ctx)
        assert ctx.params is ctx.trainer.ps.params and ctx.step == ctx.trainer.step
        assert torch.equal(ctx.gt, ctx.trainer.views.images[ctx.view_id])
        return _rgb_loss(ctx)

    tr = _trainer(tmp_path, loss_fn)
    for _ in range(3):
        tr.train_iteration()
    assert [c.step for c in seen] == [1, 2, 3]
    assert sorted({c.view_id for c in seen[:2]}) == [0, 1]          # both views before a repeat
    with pytest.raises(dataclasses.FrozenInstanceError):
        seen[0].step = 7


def test_a_methods_own_strategy_replaces_densification(tmp_path):
    strat = CountingStrategy()
    tr = _trainer(tmp_path, _rgb_loss, strategy=strat)
    assert tr.strategy is strat and strat.calls == [("initialize", 0)]
    infos = [tr.train_iteration().densify for _ in range(2)]
    assert strat.calls[1:] == [("post_backward", 1), ("post_optimizer", 1), ("post_backward", 2),
                               ("post_optimizer", 2)]
    assert infos == [{}, {"counted": 2}]                  # what the loop logs as `densify`
    st = tr.state()
    assert st["densify"] == {"n_calls": 5}                # the checkpoint holds the strategy's state
    tr2 = _trainer(tmp_path, _rgb_loss, strategy=CountingStrategy())
    tr2.load_state(st)
    assert tr2.strategy.loaded == {"n_calls": 5} and tr2.step == 2


def test_the_default_strategy_is_3dgs_density_control_and_can_be_off(tmp_path):
    tr = _trainer(tmp_path, _rgb_loss)
    assert isinstance(tr.strategy, DefaultStrategy) and tr.strategy.enabled
    assert tr.strategy.cfg is tr.cfg["train"]["densify"]
    off = _trainer(tmp_path, _rgb_loss, densify=False)
    assert not off.strategy.enabled
    n = off.ps.num
    for _ in range(3):
        assert off.train_iteration().densify == {}
    assert off.ps.num == n and float(off.strategy.stats.count.sum()) == 0.0
    assert set(off.state()["densify"]) == {"grad", "count", "max_radii"}   # the checkpoint layout of before


def test_with_field_gives_the_method_with_another_field_and_leaves_it_as_it_was():
    m = Method()
    a, _ = init_field(None, None, "random", 8, np.zeros(3), 1.0, 0, 0, seed=0)
    b = a.subset(torch.arange(8) < 3)
    m.field, m.config, m.info = a, {"k": 1}, {"init": "x"}
    probe = m.with_field(b)
    assert probe.field is b and m.field is a
    assert probe.config is m.config and type(probe) is Method
