"""3D point-level protocol: Gaussian classes, point classes, point mIoU / mAcc on hand-made point sets.

Every expected value is worked out by hand in the comments, not computed by the code under test.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from gsbench.errors import InputError
from gsbench.metrics.points3d import gaussian_classes, point_classes, point_miou_macc

# Three Gaussians on the x axis at x = 0, 10, 20; three classes with one-hot text features.
MEANS = np.array([[0.0, 0, 0], [10.0, 0, 0], [20.0, 0, 0]])
TEXTS = np.eye(3) * 4.0                     # the scale of a text row must not matter
FEATURES = np.array([[2.0, 0.5, 0.1],       # cos largest with class 0
                     [0.2, 3.0, 1.0],       # class 1
                     [-1.0, 0.3, 0.9]])     # class 2 (0.9 > 0.3 > -1)
# Five points on the x axis.
POINTS = np.array([[1.0, 0, 0], [4.0, 0, 0], [6.0, 0, 0], [16.0, 0, 0], [30.0, 0, 0]])


def test_gaussian_classes_argmax_cosine():
    got = gaussian_classes(FEATURES, TEXTS, np.full(3, 0.9), 0.1)
    np.testing.assert_array_equal(got, [0, 1, 2])
    assert got.dtype == np.int64


def test_gaussian_classes_cosine_not_dot_product():
    # text rows of different length: class 0 = [10, 0], class 1 = [0, 1]. Feature [1, 2]:
    # dot products 10 and 2 would pick class 0, cosines 1/sqrt(5) < 2/sqrt(5) pick class 1.
    got = gaussian_classes([[1.0, 2.0]], [[10.0, 0.0], [0.0, 1.0]], [1.0], 0.0)
    np.testing.assert_array_equal(got, [1])


def test_gaussian_classes_opacity_floor_and_zero_feature():
    feats = np.vstack([FEATURES, np.zeros((1, 3)), [[1.0, 1.0, 0.0]]])
    opacity = np.array([0.05, 0.1, 0.9, 0.9, 0.9])
    got = gaussian_classes(feats, TEXTS, opacity, 0.1)
    # G0: 0.05 < 0.1 -> -1; G1: 0.1 is not below the floor -> kept, class 1; G2: class 2;
    # G3: zero feature -> -1 (not NaN, not class 0); G4: cos 1/sqrt(2) with classes 0 and 1 -> tie -> 0.
    np.testing.assert_array_equal(got, [-1, 1, 2, -1, 0])


def test_gaussian_classes_accepts_torch_and_column_opacity():
    got = gaussian_classes(torch.tensor(FEATURES, dtype=torch.float32), torch.tensor(TEXTS),
                           torch.full((3, 1), 0.5), 0.2)
    np.testing.assert_array_equal(got, [0, 1, 2])


def test_point_classes_nearest_three_gaussians_five_points():
    # x=1 -> G0 (1 vs 9); x=4 -> G0 (4 vs 6); x=6 -> G1 (4 vs 6); x=16 -> G2 (4 vs 6); x=30 -> G2 (10).
    got = point_classes(POINTS, MEANS, np.array([0, 1, 2]))
    np.testing.assert_array_equal(got, [0, 0, 1, 2, 2])


def test_opacity_floor_removes_nearest_gaussian_so_next_decides():
    # G0 falls below the floor: x=1 and x=4 now take G1 (distances 9 and 6), the rest as before.
    cls = gaussian_classes(FEATURES, TEXTS, np.array([0.05, 0.9, 0.9]), 0.1)
    np.testing.assert_array_equal(cls, [-1, 1, 2])
    got = point_classes(POINTS, MEANS, cls)
    np.testing.assert_array_equal(got, [1, 1, 1, 2, 2])


def test_point_classes_nearest_exact_tie_takes_lowest_class():
    # x=5 is at distance 5 from G0 (class 2) and G1 (class 1): the lowest class, 1, in either order.
    means = np.array([[0.0, 0, 0], [10.0, 0, 0]])
    point = np.array([[5.0, 0, 0]])
    np.testing.assert_array_equal(point_classes(point, means, np.array([2, 1])), [1])
    np.testing.assert_array_equal(point_classes(point, means[::-1], np.array([1, 2])), [1])


def test_point_classes_no_classed_gaussian():
    np.testing.assert_array_equal(point_classes(POINTS, MEANS, np.array([-1, -1, -1])), [-1] * 5)
    got = point_classes(POINTS, MEANS, np.array([-1, -1, -1]), mode="radius", radius=100.0)
    np.testing.assert_array_equal(got, [-1] * 5)


RADIUS_MEANS = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.0, 1, 0], [0.0, 0, 1], [10.0, 0, 0]])
RADIUS_CLASSES = np.array([2, 0, 2, 0, 1])


def test_point_classes_radius_tie_and_empty_neighbourhood():
    points = np.array([[0.0, 0, 0], [10.0, 0, 0.5], [50.0, 50, 50]])
    got = point_classes(points, RADIUS_MEANS, RADIUS_CLASSES, mode="radius", radius=1.0)
    # origin: G0 at 0, G1..G3 at exactly 1.0 (<= radius counts) -> votes class 2: 2, class 0: 2 -> tie -> 0
    #   (nearest mode would say 2, the class of G0 at distance 0);
    # (10, 0, 0.5): only G4 at 0.5 -> 1; (50, 50, 50): nothing within 1 -> -1.
    np.testing.assert_array_equal(got, [0, 1, -1])
    np.testing.assert_array_equal(point_classes(points[:1], RADIUS_MEANS, RADIUS_CLASSES), [2])


def test_point_classes_radius_majority():
    # (-0.5, 0.5, 0), radius 1.5: G0 0.707 (2), G1 sqrt(2.5)=1.58 (out), G2 0.707 (2),
    # G3 sqrt(1.5)=1.22 (0), G4 far -> votes 2: 2, 0: 1 -> 2.
    # (0.9, 0, 0.9), radius 1.5: G0 1.27 (2), G1 0.906 (0), G2 sqrt(2.62)=1.62 (out), G3 0.906 (0) -> 0.
    points = np.array([[-0.5, 0.5, 0], [0.9, 0, 0.9]])
    got = point_classes(points, RADIUS_MEANS, RADIUS_CLASSES, mode="radius", radius=1.5)
    np.testing.assert_array_equal(got, [2, 0])


def test_point_miou_macc_five_points():
    # pred from the nearest test, gt with the x=4 point labelled class 1:
    # class 0: TP 1, FP 1 (x=4), FN 0 -> IoU 1/2, Acc 1/1
    # class 1: TP 1, FP 0, FN 1 (x=4) -> IoU 1/2, Acc 1/2
    # class 2: TP 2, FP 0, FN 0 -> IoU 1, Acc 1
    # mIoU = (0.5 + 0.5 + 1) / 3 = 2/3; mAcc = (1 + 0.5 + 1) / 3 = 5/6
    s = point_miou_macc(np.array([0, 0, 1, 2, 2]), np.array([0, 1, 1, 2, 2]), 3)
    assert s.miou == pytest.approx(2 / 3)
    assert s.macc == pytest.approx(5 / 6)
    assert s.iou == pytest.approx({0: 0.5, 1: 0.5, 2: 1.0})
    assert s.acc == pytest.approx({0: 1.0, 1: 0.5, 2: 1.0})
    assert s.present == (0, 1, 2)
    assert (s.n_points, s.n_unclassified) == (5, 0)


def test_unclassified_point_counts_as_wrong():
    # pred [0, 1, -1] vs gt [0, 1, 1]: class 0: IoU 1, Acc 1; class 1: TP 1, FN 1, FP 0 -> IoU 1/2, Acc 1/2
    # (the -1 is an FP of no class). mIoU = mAcc = 0.75.
    s = point_miou_macc([0, 1, -1], [0, 1, 1], 2)
    assert s.miou == pytest.approx(0.75)
    assert s.macc == pytest.approx(0.75)
    assert s.n_unclassified == 1


def test_class_absent_from_gt_not_counted():
    # 4 classes; gt has classes 0 and 1 only; one class-0 point is predicted class 3.
    # class 0: TP 1, FN 1 -> IoU 1/2, Acc 1/2; class 1: IoU 1, Acc 1. mIoU = mAcc = 0.75
    # (counting class 3 with IoU 0 would give 0.5; class 2 appears nowhere).
    s = point_miou_macc([0, 3, 1, 1], [0, 0, 1, 1], 4)
    assert s.present == (0, 1)
    assert s.miou == pytest.approx(0.75)
    assert s.macc == pytest.approx(0.75)
    assert set(s.iou) == {0, 1}


def test_unlabelled_gt_points_are_not_scored():
    # the second point has no GT label: its prediction (class 0) is no FP; class 1: IoU 1.
    s = point_miou_macc([1, 0], [1, -1], 2)
    assert (s.miou, s.macc, s.present, s.n_points) == (1.0, 1.0, (1,), 1)
    empty = point_miou_macc([0, 1], [-1, -1], 2)
    assert (empty.miou, empty.macc, empty.present) == (None, None, ())


@pytest.mark.parametrize("call, message", [
    (lambda: gaussian_classes(FEATURES, TEXTS[:, :2], np.ones(3), 0.1), "text_features"),
    (lambda: gaussian_classes(FEATURES, TEXTS, np.ones(2), 0.1), "opacity"),
    (lambda: gaussian_classes(FEATURES, TEXTS, np.array([0.5, 2.0, -1.0]), 0.1), "not logits"),
    (lambda: gaussian_classes(np.array([[np.nan, 0, 0]]), TEXTS, [1.0], 0.1), "features: contains NaN"),
    (lambda: gaussian_classes(FEATURES, np.zeros((3, 3)), np.ones(3), 0.1), "zero norm"),
    (lambda: gaussian_classes(FEATURES, TEXTS, np.ones(3), float("nan")), "opacity_floor"),
    (lambda: point_classes(POINTS[:, :2], MEANS, [0, 1, 2]), "points: expected"),
    (lambda: point_classes(np.array([[np.nan, 0, 0]]), MEANS, [0, 1, 2]), "points: contains NaN"),
    (lambda: point_classes(POINTS, MEANS, [0, 1]), "gaussian_class"),
    (lambda: point_classes(POINTS, MEANS, [0.0, 1.0, 2.0]), "integer"),
    (lambda: point_classes(POINTS, MEANS, [0, 1, 2], mode="radius"), "radius"),
    (lambda: point_classes(POINTS, MEANS, [0, 1, 2], radius=1.0), "radius"),
    (lambda: point_classes(POINTS, MEANS, [0, 1, 2], mode="knn"), "mode"),
    (lambda: point_miou_macc([0, 1, 2], [0, 1], 3), "pred has shape"),
    (lambda: point_miou_macc([0, 3], [0, 1], 3), "pred: class indices"),
    (lambda: point_miou_macc([0.0, 1.0], [0, 1], 3), "integer"),
    (lambda: point_miou_macc([0], [0], 0), "num_classes"),
])
def test_bad_input_raises_value_error(call, message):
    with pytest.raises(InputError, match=message) as info:
        call()
    assert isinstance(info.value, ValueError)
