"""The rendered-depth error of the depth controls on hand-made maps."""
from __future__ import annotations

import numpy as np
import pytest

from gsbench.evaluation.depth import depth_absrel


def test_depth_absrel_hand_computed():
    pred = np.array([[1.0, 2.0], [0.0, 4.0]])
    gt = np.array([[1.0, 1.0], [2.0, 0.0]])   # the last pixel has no GT depth
    # |1-1|/1 = 0, |2-1|/1 = 1, |0-2|/2 = 1 (an empty pixel counts as 1): mean 2/3
    assert depth_absrel(pred, gt) == pytest.approx(2.0 / 3.0)
    assert depth_absrel(pred, np.full((2, 2), np.nan)) is None
