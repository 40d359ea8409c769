"""The supervision-quality diagnostic on hand-made maps."""
import numpy as np

from gsbench.priors.quality import target_classes, target_quality


def test_target_classes_take_the_nearest_text():
    masks = np.array([[0, 0, 1], [-1, 1, 1]])
    text = np.array([[1.0, 0.0], [0.0, 1.0]])
    feats = {0: np.array([0.2, 0.9]), 1: np.array([0.8, 0.1])}
    assert target_classes(masks, feats, text).tolist() == [[1, 1, 0], [-1, 0, 0]]


def test_target_quality_hand_computed():
    pred = [np.array([[0, 0, 1], [-1, 1, 1]])]
    gt = [np.array([[0, 1, 1], [0, 1, -1]])]
    q = target_quality(pred, gt, 3)
    # GT pixels: 5; right: (0,0) class 0, (0,2) class 1, (1,1) class 1 -> 3/5
    assert q["pixel_acc"] == 3 / 5
    # class 0: gt {(0,0),(1,0)}, pred {(0,0),(0,1)} -> 1/3; class 1: gt {(0,1),(0,2),(1,1)},
    # pred {(0,2),(1,1),(1,2)} -> 2/4; class 2 absent -> None
    assert q["iou"] == [1 / 3, 0.5, None]
    assert q["miou"] == (1 / 3 + 0.5) / 2


def test_target_quality_without_gt_pixels():
    q = target_quality([np.zeros((2, 2), int)], [np.full((2, 2), -1)], 2)
    assert q["pixel_acc"] is None and q["iou"] == [0.0, None] and q["miou"] == 0.0   # class 0 predicted, never true
