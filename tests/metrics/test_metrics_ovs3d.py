"""3D-OVS protocol: argmax prediction, per (view, class) IoU / BIoU, pixel accuracy, scene means."""
from __future__ import annotations

import numpy as np
import pytest

from gsbench.errors import InputError
from gsbench.metrics import Ovs3dView, evaluate_ovs3d_scene, ovs3d_predict, ovs3d_view_metrics, resize_nearest

CLASSES = ["apple", "banana", "cup"]


def test_predict_argmax_of_cosine():
    f = np.array([[[1.0, 0.2], [0.1, 1.0]], [[5.0, 4.0], [0.0, 0.0]]])
    t = np.array([[3.0, 0.0], [0.0, 0.5]])          # scale of the text rows is irrelevant
    pred = ovs3d_predict(f, t)
    # [5, 4] is closer to x; a zero feature has cosine 0 with both: tie -> first class
    np.testing.assert_array_equal(pred, [[0, 1], [0, 0]])
    assert pred.dtype == np.int32
    np.testing.assert_array_equal(ovs3d_predict(f * 7.0, t), pred)


def _view():
    pred = np.zeros((4, 4), np.int32)
    pred[:, 2:] = 1                                 # left half apple, right half banana
    g_apple = np.zeros((4, 4), bool)
    g_apple[:, :3] = True
    g_banana = np.zeros((4, 4), bool)
    g_banana[:, 3] = True
    return pred, {"apple": g_apple, "banana": g_banana}


def test_view_metrics_hand():
    pred, gt = _view()
    m = ovs3d_view_metrics(pred, gt, CLASSES)
    assert m["iou"] == pytest.approx({"apple": 8 / 12, "banana": 4 / 8, "cup": 0.0})   # cup: empty union -> 0
    # d = 1 on 4x4. GT apple band: 12 pixels minus (1,1), (2,1) = 10; predicted apple band: all 8;
    # shared 6 -> 6 / 12. Banana: predicted band 8, GT band 4, all shared -> 4 / 8.
    assert m["biou"] == pytest.approx({"apple": 0.5, "banana": 0.5, "cup": 0.0})
    assert m["pixel_acc"] == pytest.approx(12 / 16)


def test_gt_resized_nearest():
    pred, gt = _view()
    big = {k: np.kron(v, np.ones((3, 3), bool)) for k, v in gt.items()}   # 12x12 GT
    m = ovs3d_view_metrics(pred, big, CLASSES)
    assert m["iou"] == pytest.approx({"apple": 8 / 12, "banana": 0.5, "cup": 0.0})
    np.testing.assert_array_equal(resize_nearest(big["apple"], 4, 4), gt["apple"])


def test_scene_means_and_missing():
    pred, gt = _view()
    perfect = np.zeros((4, 4), np.int32)
    perfect[:, 3] = 1
    views = [Ovs3dView("v0", pred, gt), Ovs3dView("v1", perfect, gt)]
    res = evaluate_ovs3d_scene(views, CLASSES)
    # v1: apple IoU 1, banana IoU 1, cup 0 (empty union); BIoU likewise
    assert res.miou == pytest.approx((8 / 12 + 0.5 + 0 + 1 + 1 + 0) / 6)
    assert res.mbiou == pytest.approx((0.5 + 0.5 + 0 + 1 + 1 + 0) / 6)
    assert res.pixel_acc == pytest.approx((0.75 + 1.0) / 2)
    missing = views + [Ovs3dView("v2", None, gt)]
    with pytest.raises(InputError, match="v2"):
        evaluate_ovs3d_scene(missing, CLASSES)
    skip = evaluate_ovs3d_scene(missing, CLASSES, missing="skip")
    assert skip.miou == pytest.approx(res.miou) and skip.skipped[0]["view"] == "v2"
    zero = evaluate_ovs3d_scene(missing, CLASSES, missing="zero")
    assert zero.miou == pytest.approx((8 / 12 + 0.5 + 2) / 9) and zero.pixel_acc == pytest.approx(1.75 / 3)


def test_bad_input():
    pred, gt = _view()
    with pytest.raises(InputError):
        ovs3d_view_metrics(pred, {"pear": gt["apple"]}, CLASSES)
    with pytest.raises(InputError):
        ovs3d_view_metrics(pred + 5, gt, CLASSES)
    with pytest.raises(InputError):
        ovs3d_view_metrics(pred.astype(float), gt, CLASSES)
    with pytest.raises(InputError):
        ovs3d_predict(np.ones((2, 2, 3)), np.zeros((2, 3)))     # zero text embedding
