"""Scoring folders of predicted masks against LERF-OVS labels and a 3D-OVS layout."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from paths import REPO_ROOT, SHARED_DATA

from gsbench.errors import InputError
from gsbench.evaluation import score_mask_folder

SHARED = SHARED_DATA
LERF_DIR = SHARED / "lerf_ovs_labels" / "waldo_kitchen"
LABEL = LERF_DIR / "frame_00066.json"
needs_shared = pytest.mark.skipif(not LABEL.exists(), reason=f"real LERF-OVS label file not found at {LABEL} "
                                  "(../shared/data is absent in a fresh clone)")


def _gt_masks_independent(label: Path) -> tuple[int, int, dict[str, np.ndarray]]:
    """Rasterise the label file here, independently of gsbench: cv2.fillPoly on int32 points, OR per category."""
    d = json.loads(label.read_text())
    w, h = d["info"]["width"], d["info"]["height"]
    out: dict[str, np.ndarray] = {}
    for o in d["objects"]:
        m = np.zeros((h, w), np.uint8)
        cv2.fillPoly(m, [np.asarray(o["segmentation"], np.float64).astype(np.int32).reshape(-1, 1, 2)], 1)
        out[o["category"]] = out.get(o["category"], np.zeros((h, w), bool)) | m.astype(bool)
    return w, h, out


def _write(path: Path, mask: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), (mask.astype(np.uint8) * 255))


@needs_shared
def test_lerf_real_label_file_missing_prediction_reported(tmp_path):
    w, h, gt = _gt_masks_independent(LABEL)
    assert sorted(gt) == ["plastic ladle", "pot", "refrigerator", "spatula"]
    pred = tmp_path / "pred"
    frame = pred / "frame_00066"
    _write(frame / "pot.png", gt["pot"])                                 # perfect: IoU 1
    _write(frame / "refrigerator.png", np.ones((h, w), bool))           # whole image: IoU = area / (w h)
    _write(frame / "plastic ladle.png", np.zeros((h, w), bool))          # empty: IoU 0
    # spatula: no file -> reported missing, counted as 0
    res = score_mask_folder(pred, LERF_DIR, "lerf", out_dir=tmp_path / "out")

    fridge = gt["refrigerator"].sum() / float(w * h)
    expected = (1.0 + fridge + 0.0 + 0.0) / 4.0
    assert res["metrics"]["miou_lerf"] == pytest.approx(expected, abs=1e-9)
    assert res["missing"]["count"] == 1
    assert res["missing"]["files"] == ["frame_00066/spatula.png"]
    pairs = {p["query"]: p for p in res["pairs"]}
    assert pairs["spatula"]["missing"] is True and pairs["spatula"]["iou"] == 0.0
    assert pairs["pot"]["iou"] == pytest.approx(1.0)
    assert len(res["pairs"]) == 4                                        # nothing dropped
    written = json.loads((tmp_path / "out" / "results.json").read_text())
    assert written["protocol"] == "lerf"
    assert "miou_lerf" in written["metric_impl"]
    assert written["missing"]["count"] == 1
    assert written["skipped"]["loc_acc_lerf"]                            # not computable from masks, says why


@needs_shared
def test_lerf_prediction_at_lower_resolution_is_compared_at_its_resolution(tmp_path):
    w, h, gt = _gt_masks_independent(LABEL)
    pred = tmp_path / "pred" / "frame_00066"
    for q, m in gt.items():
        small = cv2.resize(m.astype(np.uint8), (w // 2, h // 2), interpolation=cv2.INTER_NEAREST_EXACT)
        _write(pred / f"{q}.png", small.astype(bool))
    res = score_mask_folder(tmp_path / "pred", LERF_DIR, "lerf")
    # the GT is resized by centre sampling (PIL NEAREST's rule), so every pair matches exactly
    assert res["metrics"]["miou_lerf"] == pytest.approx(1.0)
    assert res["missing"]["count"] == 0
    assert (tmp_path / "pred" / "results.json").exists()


def _ovs_layout(root: Path) -> None:
    """3 views of 8x10, classes 'b' then 'a' in the file (sorted on load: a, b)."""
    (root / "images").mkdir(parents=True)
    for k in range(3):
        cv2.imwrite(str(root / "images" / f"img_{k:02d}.png"), np.zeros((8, 10, 3), np.uint8))
    seg = root / "segmentations"
    seg.mkdir()
    (seg / "classes.txt").write_text("b\na\n")
    for k in range(3):
        a = np.zeros((8, 10), bool)
        a[:, :5] = True                      # left half = a (40 px)
        b = np.zeros((8, 10), bool)
        b[:, 5:] = True                      # right half = b (40 px)
        _write(seg / str(k) / "a.png", a)
        _write(seg / str(k) / "b.png", b)


def test_3dovs_both_formats_and_missing(tmp_path):
    layout = tmp_path / "scene"
    _ovs_layout(layout)
    pred = tmp_path / "pred"
    # view 0: per-class masks, a predicted on columns 0..3 (32 px, inside GT a): IoU(a) = 32/40;
    #         b predicted on columns 4..9 (48 px; GT b 40 px, overlap 40): IoU(b) = 40/48
    a = np.zeros((8, 10), bool)
    a[:, :4] = True
    b = np.zeros((8, 10), bool)
    b[:, 4:] = True
    _write(pred / "0" / "a.png", a)
    _write(pred / "0" / "b.png", b)
    # view 1 (named by its image stem): a class-index map, everything class 0 (= 'a'):
    #   IoU(a) = 40/80, IoU(b) = 0/40 = 0, pixel acc = 40/80
    cv2.imwrite(str(pred / "img_01.png"), np.zeros((8, 10), np.uint8))
    # view 2: nothing -> missing, scored 0 for both classes
    res = score_mask_folder(pred, layout, "3dovs")
    ious = [32 / 40, 40 / 48, 40 / 80, 0.0, 0.0, 0.0]
    assert res["classes"] == ["a", "b"]
    assert res["metrics"]["miou_3dovs"] == pytest.approx(sum(ious) / 6)
    assert res["missing"]["count"] == 1 and res["missing"]["files"] == ["2 (whole view)"]
    assert len(res["pairs"]) == 6
    # per-class masks do not define one class per pixel -> pixel accuracy skipped with a reason
    assert res["metrics"]["pixel_acc_3dovs"] is None
    assert "pixel_acc_3dovs" in res["skipped"]
    assert res["per_view"]["pixel_acc_3dovs"][1] == pytest.approx(0.5)


def test_3dovs_missing_class_file_counted(tmp_path):
    layout = tmp_path / "scene"
    _ovs_layout(layout)
    pred = tmp_path / "pred"
    full_a = np.zeros((8, 10), bool)
    full_a[:, :5] = True
    for k in range(3):
        _write(pred / str(k) / "a.png", full_a)       # b.png never written
    res = score_mask_folder(pred, layout, "3dovs")
    assert res["missing"]["count"] == 3
    assert res["metrics"]["miou_3dovs"] == pytest.approx(0.5)   # a = 1, b = 0 (missing) in each view


def test_bad_inputs_name_the_problem(tmp_path):
    layout = tmp_path / "scene"
    _ovs_layout(layout)
    (tmp_path / "pred").mkdir()
    with pytest.raises(InputError, match="prediction folder not found"):
        score_mask_folder(tmp_path / "nope", layout, "3dovs")
    with pytest.raises(InputError, match="classes.txt"):
        score_mask_folder(tmp_path / "pred", tmp_path / "pred", "3dovs")
    with pytest.raises(InputError, match=r"holds no frame_\*.json label files; LERF-OVS label files usually"):
        score_mask_folder(tmp_path / "pred", layout, "lerf")
    bad = tmp_path / "pred" / "0.png"
    cv2.imwrite(str(bad), np.full((8, 10), 7, np.uint8))
    with pytest.raises(InputError, match="class index"):
        score_mask_folder(tmp_path / "pred", layout, "3dovs")


@needs_shared
def test_cli_scores_mask_folder(tmp_path):
    w, h, gt = _gt_masks_independent(LABEL)
    pred = tmp_path / "pred" / "frame_00066"
    _write(pred / "pot.png", gt["pot"])
    out = subprocess.run([sys.executable, "-m", "gsbench.cli", "eval", "--masks", str(tmp_path / "pred"),
                          "--layout", str(LERF_DIR), "--protocol", "lerf", "--out", str(tmp_path / "o")],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "missing predictions: 3" in out.stdout
    res = json.loads((tmp_path / "o" / "results.json").read_text())
    assert res["metrics"]["miou_lerf"] == pytest.approx(0.25)


@needs_shared
def test_label_masks_for_run_evaluation_match_independent_raster():
    """evaluate_run's LERF GT: polygons rasterised at the label size, resized NEAREST; boxes scaled."""
    from gsbench.datasets.ovs import read_lerf_label
    from gsbench.evaluation import label_masks
    w, h, gt = _gt_masks_independent(LABEL)
    _, objs = read_lerf_label(LABEL)
    masks, boxes = label_masks(objs, w, h, 197, 145)          # 1/5 of 985 x 725
    assert sorted(masks) == sorted(gt)
    for q, m in gt.items():
        ref = cv2.resize(m.astype(np.uint8), (197, 145), interpolation=cv2.INTER_NEAREST_EXACT).astype(bool)
        assert masks[q].shape == (145, 197) and np.array_equal(masks[q], ref)
    raw = {o["category"]: o["bbox"] for o in json.loads(LABEL.read_text())["objects"]}
    for q, b in boxes.items():
        assert b.shape == (1, 4)
        assert np.allclose(b[0], np.asarray(raw[q], float) / 5.0)


def test_results_machine_records_git_sha(tmp_path):
    """results.json `machine` is the run environment capture (gsbench.runs.env_info) and carries the
    checkout's HEAD sha (read independently here)."""
    layout = tmp_path / "scene"
    _ovs_layout(layout)
    (tmp_path / "pred").mkdir()
    score_mask_folder(tmp_path / "pred", layout, "3dovs", out_dir=tmp_path / "out")
    root = REPO_ROOT
    on_disk = json.loads((tmp_path / "out" / "results.json").read_text())["machine"]
    if (root / ".git").exists():
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True).stdout.strip()
        assert on_disk["git_sha"] == head and len(head) == 40
        changed = subprocess.run(["git", "diff", "HEAD", "--quiet"], cwd=root).returncode == 1
        assert on_disk["git_dirty"] is changed      # uncommitted code is not credited to HEAD alone
    else:
        assert on_disk["git_sha"] is None and on_disk["git_dirty"] is None


def test_git_dirty_follows_an_edit_of_a_tracked_file(tmp_path):
    """git_state() in a throw-away repository holding gsbench/environment.py: clean after the commit,
    dirty once a tracked file changes, and an untracked file does not count."""
    clone = tmp_path / "clone"
    (clone / "gsbench").mkdir(parents=True)
    (clone / "gsbench" / "environment.py").write_text((REPO_ROOT / "gsbench" / "environment.py").read_text())
    (clone / "gsbench" / "__init__.py").write_text("")
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-c", "commit.gpgsign=false"]
    subprocess.run([*git, "init", "-q"], cwd=clone, check=True)
    subprocess.run([*git, "add", "-A"], cwd=clone, check=True)
    subprocess.run([*git, "commit", "-q", "-m", "x"], cwd=clone, check=True)
    code = ("import importlib.util,sys;s=importlib.util.spec_from_file_location('e',sys.argv[1]);"
            "m=importlib.util.module_from_spec(s);s.loader.exec_module(m);print(m.git_state()[1])")
    run = lambda: subprocess.run([sys.executable, "-c", code, str(clone / "gsbench" / "environment.py")],  # noqa: E731
                                 capture_output=True, text=True, check=True).stdout.strip()
    assert run() == "False"
    (clone / "notes.txt").write_text("untracked")
    assert run() == "False"
    (clone / "gsbench" / "__init__.py").write_text("# edited\n")
    assert run() == "True"


@pytest.mark.parametrize("factor", [2, 8])
def test_gt_masks_downsampled_by_centre_sampling_score_100(tmp_path, factor):
    """Predictions equal to the GT masks, downsampled by centre sampling (PIL NEAREST's rule), score
    mIoU = mBIoU = 1 under both protocols (with cv2.INTER_NEAREST for the GT: 0.86 / 0.73 at 1/2)."""
    from gsbench.datasets.ovs import label_masks as rasterise
    from gsbench.datasets.ovs import read_lerf_label
    from gsbench.datasets.synthetic import make_scene
    scene = make_scene("tabletop-small", tmp_path / "t", seed=0, views=3)

    def down(m):
        h, w = m.shape
        return cv2.resize(m.astype(np.uint8), (w // factor, h // factor), interpolation=cv2.INTER_NEAREST_EXACT)

    for vd in sorted(p for p in (scene / "segmentations").iterdir() if p.is_dir()):
        for f in vd.glob("*.png"):
            _write(tmp_path / "p3" / vd.name / f.name, down(cv2.imread(str(f), cv2.IMREAD_UNCHANGED) == 255) > 0)
    label_dir = scene / "label" / "tabletop-small"
    for lf in sorted(label_dir.glob("frame_*.json")):
        info, objs = read_lerf_label(lf)
        for q, m in rasterise(objs, info["height"], info["width"]).items():
            _write(tmp_path / "pl" / lf.stem / f"{q}.png", down(m) > 0)
    r3 = score_mask_folder(tmp_path / "p3", scene, "3dovs")
    rl = score_mask_folder(tmp_path / "pl", label_dir, "lerf")
    assert r3["missing"]["count"] == 0 and rl["missing"]["count"] == 0
    for res, p in ((r3, "3dovs"), (rl, "lerf")):
        assert res["metrics"][f"miou_{p}"] == pytest.approx(1.0)
        assert res["metrics"][f"mbiou_{p}"] == pytest.approx(1.0)


def test_empty_gt_pair_scored_by_the_same_rule_as_the_run_path(tmp_path):
    """A label whose polygon vanishes on the prediction's grid has an empty GT there. eval --masks
    counts it with the run path's rule (metrics.lerf.evaluate_lerf_scene): IoU 0 for a non-empty
    prediction, 1 when the prediction is empty too."""
    from gsbench.metrics.lerf import LerfPair, evaluate_lerf_scene
    labels = tmp_path / "labels"
    labels.mkdir()
    obj = {"category": "dot", "bbox": [0, 0, 1, 1], "segmentation": [[0, 0], [0, 0], [0, 0]]}   # pixel (0, 0)
    (labels / "frame_00001.json").write_text(json.dumps({"info": {"width": 32, "height": 24,
                                                                  "name": "frame_00001.jpg"}, "objects": [obj]}))
    full = np.ones((12, 16), bool)
    _write(tmp_path / "some" / "frame_00001" / "dot.png", full)      # 16x12: centre sampling skips pixel (0, 0)
    _write(tmp_path / "none" / "frame_00001" / "dot.png", ~full)
    some = score_mask_folder(tmp_path / "some", labels, "lerf")
    none = score_mask_folder(tmp_path / "none", labels, "lerf")
    block = np.full((12, 16), 0.1)
    block[2:10, 3:13] = 0.9
    run_some = evaluate_lerf_scene([LerfPair("f", "dot", [block], ~full)]).miou                # predicts pixels
    run_none = evaluate_lerf_scene([LerfPair("f", "dot", [np.full((12, 16), 0.3)], ~full)]).miou  # predicts none
    assert some["pairs"][0]["iou"] == run_some == 0.0 and some["metrics"]["miou_lerf"] == 0.0
    assert none["pairs"][0]["iou"] == run_none == 1.0 and none["metrics"]["miou_lerf"] == 1.0
