"""The empty-class rule of each protocol (docs/metrics.md, docs/protocols.md), on hand cases.

3D-OVS (its reference scores each view with sklearn's jaccard_score(average=None) over every class,
zero_division 0, then np.mean over views x classes): a class with an empty GT scores 0, also when the
prediction is empty. LERF-OVS (LangSplat): a frame is queried only with its own label file's
categories; an empty GT mask scores |P & G| / |P | G|, 0 / 0 taken as 1.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from gsbench.evaluation import score_mask_folder
from gsbench.metrics.ovs3d import Ovs3dView, evaluate_ovs3d_scene, ovs3d_view_metrics

CLASSES = ["a", "b", "c"]


def _gt() -> dict[str, np.ndarray]:
    """4x4: a = the left 2 columns (8 px), b = the right 2 (8 px), c absent (no mask)."""
    a = np.zeros((4, 4), bool)
    a[:, :2] = True
    return {"a": a, "b": ~a}


def test_3dovs_empty_gt_and_empty_prediction_scores_0():
    pred = np.where(_gt()["a"], 0, 1).astype(np.int32)          # a and b exact, c nowhere
    m = ovs3d_view_metrics(pred, _gt(), CLASSES)
    assert m["iou"] == {"a": 1.0, "b": 1.0, "c": 0.0}
    assert m["biou"]["c"] == 0.0
    assert m["empty_gt"] == ["c"] and m["empty_both"] == ["c"]


def test_3dovs_empty_gt_with_a_prediction_scores_0_and_is_not_empty_both():
    pred = np.where(_gt()["a"], 0, 1).astype(np.int32)
    pred[0, 3] = 2                                                # one pixel of b predicted as c
    m = ovs3d_view_metrics(pred, _gt(), CLASSES)
    assert m["iou"] == {"a": 1.0, "b": 7 / 8, "c": 0.0}
    assert m["empty_gt"] == ["c"] and m["empty_both"] == []


def test_3dovs_scene_mean_counts_every_class_of_every_view():
    """View 1 as above (1, 1, 0); view 2 has c over the right half, no b, and predicts everything a:
    a = 8/16, b = 0 (empty/empty), c = 0/8. mIoU = (1 + 1 + 0 + 0.5 + 0 + 0) / 6; two empty/empty pairs."""
    pred1 = np.where(_gt()["a"], 0, 1).astype(np.int32)
    gt2 = {"a": _gt()["a"], "c": _gt()["b"]}
    r = evaluate_ovs3d_scene([Ovs3dView("v1", pred1, _gt()), Ovs3dView("v2", np.zeros((4, 4), np.int32), gt2)],
                             CLASSES)
    assert r.miou == pytest.approx(2.5 / 6, abs=1e-12)
    assert r.per_view[0]["miou"] == pytest.approx(2 / 3, abs=1e-12)
    assert r.empty_both == 2 and r.per_view[1]["empty_gt"] == ["b"] and r.per_view[1]["empty_both"] == ["b"]
    assert r.per_view[1]["iou"] == {"a": 0.5, "b": 0.0, "c": 0.0}
    assert r.params["empty_union"] == 0.0


def test_3dovs_mask_folder_says_how_many_pairs_are_empty(tmp_path):
    """eval --masks, 3D-OVS: the same rule, and a note with the count and the mean without them
    (a, b exact and c empty in GT and prediction: mIoU 2/3 by the rule, 1 without the pair)."""
    scene = tmp_path / "scene"
    (scene / "images").mkdir(parents=True)
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(scene / "images" / "img_0.png")
    (scene / "segmentations" / "0").mkdir(parents=True)
    (scene / "segmentations" / "classes.txt").write_text("a\nb\nc\n")
    a = np.zeros((8, 8), np.uint8)
    a[:, :4] = 255
    for name, m in (("a", a), ("b", 255 - a), ("c", np.zeros_like(a))):
        Image.fromarray(m).save(scene / "segmentations" / "0" / f"{name}.png")
    (tmp_path / "pred").mkdir()
    Image.fromarray(np.where(a > 0, 0, 1).astype(np.uint8)).save(tmp_path / "pred" / "0.png")
    res = score_mask_folder(tmp_path / "pred", scene, "3dovs")
    assert res["metrics"]["miou_3dovs"] == pytest.approx(2 / 3, abs=1e-12)
    c = [p for p in res["pairs"] if p["class"] == "c"][0]
    assert c["iou"] == 0.0 and c["empty_gt"] is True and c["empty_prediction"] is True
    note = res["notes"]["3dovs_empty_gt"]
    assert note.startswith("1 of 3 (view, class) pairs have an empty GT mask, 1 of them an empty prediction too")
    assert note.endswith("mIoU without the 1 empty/empty pairs: 1.0000")


def _label(root: Path, frame: str, objects: list[dict]) -> None:
    root.mkdir(parents=True, exist_ok=True)
    (root / f"{frame}.json").write_text(json.dumps({"info": {"width": 16, "height": 12, "name": f"{frame}.jpg"},
                                                    "objects": objects}))


def _obj(category: str, points: list) -> dict:
    return {"category": category, "bbox": [0, 0, 1, 1], "segmentation": points}


def test_lerf_empty_gt_pairs_and_queries_absent_from_a_frame(tmp_path):
    """'box' is a rectangle; 'gone' lies right of the 16x12 image (an empty GT). An empty prediction
    for 'gone' scores 1 (mIoU (1 + 1) / 2); a non-empty one 0 (mIoU 1/2). A file for a query that is
    not in the frame's label file is not scored and is listed."""
    labels = tmp_path / "labels"
    _label(labels, "frame_00001", [_obj("box", [[2, 2], [5, 2], [5, 5], [2, 5]]),
                                   _obj("gone", [[20, 2], [25, 2], [25, 5]])])
    box = np.zeros((12, 16), np.uint8)
    box[2:6, 2:6] = 255                                          # cv2.fillPoly: x 2..5, y 2..5 inclusive
    frame = tmp_path / "pred" / "frame_00001"
    frame.mkdir(parents=True)
    Image.fromarray(box).save(frame / "box.png")
    Image.fromarray(np.zeros_like(box)).save(frame / "gone.png")
    res = score_mask_folder(tmp_path / "pred", labels, "lerf")
    assert res["metrics"]["miou_lerf"] == 1.0
    gone = [p for p in res["pairs"] if p["query"] == "gone"][0]
    assert gone["iou"] == 1.0 and gone["empty_gt"] is True and gone["empty_prediction"] is True
    assert res["notes"]["lerf_empty_gt"].startswith("1 of 2 (frame, query) pairs have an empty GT mask")

    Image.fromarray(box).save(frame / "gone.png")
    assert score_mask_folder(tmp_path / "pred", labels, "lerf")["metrics"]["miou_lerf"] == 0.5

    _label(labels, "frame_00002", [_obj("box", [[2, 2], [5, 2], [5, 5], [2, 5]])])
    (tmp_path / "pred" / "frame_00002").mkdir()
    Image.fromarray(box).save(tmp_path / "pred" / "frame_00002" / "box.png")
    Image.fromarray(box).save(tmp_path / "pred" / "frame_00002" / "gone.png")   # 'gone' is not labelled there
    res = score_mask_folder(tmp_path / "pred", labels, "lerf")
    assert len(res["pairs"]) == 3
    assert res["unscored"]["count"] == 1 and res["unscored"]["files"] == ["frame_00002/gone.png"]
