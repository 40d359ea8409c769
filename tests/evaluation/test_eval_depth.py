"""The rendered-depth metrics of the depth controls (error, covered-pixel error, coverage) on hand-made maps."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from gsbench.evaluation.depth import depth_absrel, depth_covered, depth_metrics


def test_depth_absrel_hand_computed():
    pred = np.array([[1.0, 2.0], [0.0, 4.0]])
    gt = np.array([[1.0, 1.0], [2.0, 0.0]])   # the last pixel has no GT depth
    # |1-1|/1 = 0, |2-1|/1 = 1, |0-2|/2 = 1 (an empty pixel counts as 1): mean 2/3
    assert depth_absrel(pred, gt) == pytest.approx(2.0 / 3.0)
    assert depth_absrel(pred, np.full((2, 2), np.nan)) is None


def test_depth_covered_hand_computed():
    # 2x3 map: GT depth 2 everywhere but the last pixel (no depth)
    gt = np.array([[2.0, 2.0, 2.0], [2.0, 2.0, 0.0]])
    alpha = np.array([[1.0, 0.8, 0.5], [0.2, 0.0, 1.0]])
    # composited D = alpha * surface depth: surfaces at 2, 3 (wrong), 2, 2, -, 2
    pred = alpha * np.array([[2.0, 3.0, 2.0], [2.0, 0.0, 2.0]])
    err, share = depth_covered(pred, alpha, gt)
    # covered (alpha > 0.5) among the 5 GT pixels: the first two; D / alpha = 2 and 3 -> errors 0 and 0.5
    assert share == pytest.approx(2.0 / 5.0)
    assert err == pytest.approx(0.25)
    # the mixed number counts the faint and empty pixels: |2-2|, |2.4-2|, |1-2|, |0.4-2|, |0-2| over 2
    assert depth_absrel(pred, gt) == pytest.approx((0.0 + 0.2 + 0.5 + 0.8 + 1.0) / 5.0)


def test_depth_covered_nothing_covered_or_no_depth():
    gt = np.full((2, 2), 3.0)
    err, share = depth_covered(np.zeros((2, 2)), np.full((2, 2), 0.3), gt)
    assert err is None and share == 0.0
    assert depth_covered(np.zeros((2, 2)), np.ones((2, 2)), np.zeros((2, 2))) == (None, None)
    with pytest.raises(ValueError, match="threshold"):
        depth_covered(np.zeros((2, 2)), np.ones((2, 2)), gt, threshold=0.0)


def test_depth_metrics_records_the_three_numbers_per_view():
    """Two held-out views of a 2x2 render: one fully covered at the right depth, one half covered
    with its covered pixels 10 % too far; GT depth 2 everywhere."""
    alphas = {0: torch.ones(2, 2), 1: torch.tensor([[1.0, 1.0], [0.0, 0.0]])}
    surfaces = {0: torch.full((2, 2), 2.0), 1: torch.full((2, 2), 2.2)}

    class Stub:
        def render(self, cam):
            a = alphas[cam.i]
            return SimpleNamespace(depth=a * surfaces[cam.i], alpha=a)

    cams = [SimpleNamespace(i=0, width=2, height=2, name="a"), SimpleNamespace(i=1, width=2, height=2, name="b")]
    scene = SimpleNamespace(has_depth=True, cameras=cams, gt_depth=lambda i: np.full((2, 2), 2.0, np.float32))
    out = depth_metrics(Stub(), scene, [0, 1], cams)
    assert out.metrics["depth_coverage"] == pytest.approx((1.0 + 0.5) / 2)
    assert out.metrics["depth_absrel_covered"] == pytest.approx((0.0 + 0.1) / 2)
    # view b: two pixels 0.1 off, two empty (1 each) -> 0.55
    assert out.metrics["depth_absrel"] == pytest.approx((0.0 + 0.55) / 2)
    assert out.per_view["depth_coverage"] == pytest.approx([1.0, 0.5])
