"""Predicted mask files of `gsbench eval --masks` in other value conventions and sizes (issue 39):
read right when unambiguous, refused naming the file and its values or size otherwise; a huge PNG
is refused from its header. The hostile:eval battery runs the same inputs through the CLI."""
from __future__ import annotations

import json
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageFile

from gsbench.commands.hostile import run_hostile
from gsbench.commands.hostile.eval import CASES, write_zero_png
from gsbench.errors import InputError
from gsbench.evaluation import score_mask_folder
from gsbench.evaluation.mask_files import image_size

H, W = 16, 20


def _layout(root: Path) -> dict[str, np.ndarray]:
    """A 3D-OVS scene of 2 views of 20x16: class a = left 8 columns (128 px), b = the rest (192 px)."""
    (root / "images").mkdir(parents=True)
    a = np.zeros((H, W), bool)
    a[:, :8] = True
    gt = {"a": a, "b": ~a}
    for k in range(2):
        Image.fromarray(np.zeros((H, W, 3), np.uint8)).save(root / "images" / f"img_{k}.png")
        (root / "segmentations" / str(k)).mkdir(parents=True)
        for c, m in gt.items():
            Image.fromarray(m.astype(np.uint8) * 255).save(root / "segmentations" / str(k) / f"{c}.png")
    (root / "segmentations" / "classes.txt").write_text("a\nb\n")
    return gt


def _predict(pred: Path, masks: dict[str, np.ndarray], to_image, fmt: str = "PNG") -> None:
    for k in range(2):
        (pred / str(k)).mkdir(parents=True, exist_ok=True)
        for c, m in masks.items():
            to_image(m).save(pred / str(k) / f"{c}.png", format=fmt)


def _as(values: list, dtype):
    return lambda m: Image.fromarray(np.where(m, values[1], values[0]).astype(dtype))


@pytest.mark.parametrize("values,dtype,fmt", [([0, 1], np.uint8, "PNG"), ([0, 255], np.uint8, "PNG"),
                                              ([0, 65535], np.uint16, "PNG"), ([0, 1], np.uint16, "PNG"),
                                              ([0.0, 1.0], np.float32, "TIFF")])
def test_binary_conventions_are_read_as_masks(tmp_path, values, dtype, fmt):
    """Predictions equal to the GT in each unambiguous convention score 1 (0/1 masks read 0 before)."""
    gt = _layout(tmp_path / "scene")
    _predict(tmp_path / "pred", gt, _as(values, dtype), fmt)
    res = score_mask_folder(tmp_path / "pred", tmp_path / "scene", "3dovs")
    assert res["metrics"]["miou_3dovs"] == 1.0 and res["metrics"]["mbiou_3dovs"] == 1.0


def test_single_valued_full_mask_is_the_whole_image(tmp_path):
    """Every pixel 1 is the whole image: IoU(a) = 128/320, IoU(b) = 192/320 in each view."""
    gt = _layout(tmp_path / "scene")
    _predict(tmp_path / "pred", {c: np.ones_like(m) for c, m in gt.items()}, _as([0, 1], np.uint8))
    res = score_mask_folder(tmp_path / "pred", tmp_path / "scene", "3dovs")
    assert res["metrics"]["miou_3dovs"] == pytest.approx((128 / 320 + 192 / 320) / 2, abs=1e-12)


@pytest.mark.parametrize("values,dtype,fmt,message", [
    ([0, 128], np.uint8, "PNG", r"a\.png: not a binary mask: values 0, 128 \(8-bit"),
    ([0, 255], np.uint16, "PNG", r"a\.png: not a binary mask: values 0, 255 \(16-bit image; a mask holds 0 and 65535"),
    ([0.0, 0.5], np.float32, "TIFF", r"a\.png: not a binary mask: values 0, 0\.5 \(float image; a mask holds 0 and 1"),
    ([0.0, np.nan], np.float32, "TIFF", r"a\.png: the mask holds NaN"),
    ([-1.0, 1.0], np.float32, "TIFF", r"values -1, 1"),
])
def test_ambiguous_values_are_refused_naming_file_and_values(tmp_path, values, dtype, fmt, message):
    gt = _layout(tmp_path / "scene")
    _predict(tmp_path / "pred", gt, _as(values, dtype), fmt)
    with pytest.raises(InputError, match=message):
        score_mask_folder(tmp_path / "pred", tmp_path / "scene", "3dovs")


def test_soft_mask_is_refused_with_a_summary_of_its_values(tmp_path):
    gt = _layout(tmp_path / "scene")
    ramp = (np.arange(H * W) % 200).astype(np.uint8).reshape(H, W)
    _predict(tmp_path / "pred", gt, lambda m: Image.fromarray(ramp))
    with pytest.raises(InputError, match=r"not a binary mask: 200 distinct values from 0 to 199"):
        score_mask_folder(tmp_path / "pred", tmp_path / "scene", "3dovs")


def test_colour_mask_with_differing_channels_is_refused(tmp_path):
    gt = _layout(tmp_path / "scene")
    red = np.zeros((H, W, 3), np.uint8)
    red[..., 0] = 255
    _predict(tmp_path / "pred", gt, lambda m: Image.fromarray(red))
    with pytest.raises(InputError, match="colour image"):
        score_mask_folder(tmp_path / "pred", tmp_path / "scene", "3dovs")


def test_palette_class_map_is_read_as_its_indices(tmp_path):
    """Index 0 = a, 1 = b, drawn with colours that are not the indices: mIoU 1, pixel accuracy 1."""
    gt = _layout(tmp_path / "scene")
    im = Image.fromarray(np.where(gt["a"], 0, 1).astype(np.uint8)).convert("P")
    im.putpalette([200, 10, 10, 10, 200, 10] + [0] * 762)
    (tmp_path / "pred").mkdir()
    for k in range(2):
        im.save(tmp_path / "pred" / f"{k}.png")
    res = score_mask_folder(tmp_path / "pred", tmp_path / "scene", "3dovs")
    assert res["metrics"]["miou_3dovs"] == 1.0 and res["metrics"]["pixel_acc_3dovs"] == 1.0


def test_class_map_cannot_name_more_than_255_classes(tmp_path):
    _layout(tmp_path / "scene")
    seg = tmp_path / "scene" / "segmentations"
    (seg / "classes.txt").write_text("\n".join(f"c{k}" for k in range(300)))
    for k in range(2):
        for c in ("a", "b"):
            (seg / str(k) / f"{c}.png").rename(seg / str(k) / f"c{ord(c) - 97}.png")
    (tmp_path / "pred").mkdir()
    Image.fromarray(np.zeros((H, W), np.uint8)).save(tmp_path / "pred" / "0.png")
    with pytest.raises(InputError, match=r"0\.png: a class-index map names classes 0 to 254 .* 300 classes"):
        score_mask_folder(tmp_path / "pred", tmp_path / "scene", "3dovs")


@pytest.mark.parametrize("size,message", [((1, 1), r"1x1 is too small .*20x16; the smallest scored size is 8x8"),
                                          ((7, 7), r"7x7 is too small"),
                                          ((40, 32), r"40x32 is larger than .*20x16"),
                                          ((20, 8), r"20x8 has another aspect ratio")])
def test_sizes_the_protocol_does_not_score_are_refused(tmp_path, size, message):
    gt = _layout(tmp_path / "scene")
    _predict(tmp_path / "pred", gt, lambda m: Image.fromarray(np.zeros(size[::-1], np.uint8)))
    with pytest.raises(InputError, match=r"pred[/\\]0[/\\]a\.png: prediction size " + message):
        score_mask_folder(tmp_path / "pred", tmp_path / "scene", "3dovs")


def test_half_size_prediction_is_scored_at_its_size(tmp_path):
    """10x8 (1/2) is within the bound: a = the left 4 columns of 10 at that size."""
    _layout(tmp_path / "scene")
    a = np.zeros((8, 10), bool)
    a[:, :4] = True
    _predict(tmp_path / "pred", {"a": a, "b": ~a}, _as([0, 255], np.uint8))
    res = score_mask_folder(tmp_path / "pred", tmp_path / "scene", "3dovs")
    assert res["metrics"]["miou_3dovs"] == 1.0 and res["resolution"]["3dovs/masks"].startswith("10x8")


def _lerf_labels(root: Path) -> Path:
    """One 32x24 label file with the query 'box' (a rectangle)."""
    root.mkdir(parents=True)
    obj = {"category": "box", "bbox": [4, 4, 12, 10], "segmentation": [[4, 4], [12, 4], [12, 10], [4, 10]]}
    (root / "frame_00001.json").write_text(json.dumps({"info": {"width": 32, "height": 24,
                                                                "name": "frame_00001.jpg"}, "objects": [obj]}))
    return root


def test_huge_png_refused_from_header_without_decoding(tmp_path, monkeypatch):
    """A valid 16000x12000 PNG (192 MB of pixels): refused within 10 s, with no image decoded and
    no Python allocation near the image's size."""
    labels = _lerf_labels(tmp_path / "labels")
    f = tmp_path / "pred" / "frame_00001" / "box.png"
    write_zero_png(f, 16000, 12000)
    assert f.stat().st_size < 1_000_000 and image_size(f) == (16000, 12000)

    def no_decode(self, *args, **kwargs):
        raise AssertionError("the image was decoded")
    monkeypatch.setattr(ImageFile.ImageFile, "load", no_decode)
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(InputError, match=r"box\.png: prediction size 16000x12000 is larger than .*32x24"):
            score_mask_folder(tmp_path / "pred", labels, "lerf")
        seconds = time.perf_counter() - t0
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert seconds < 10.0
    assert peak < 20_000_000        # the decoded image alone is 192 MB


def test_lerf_zero_one_masks_read_and_tiny_refused(tmp_path):
    labels = _lerf_labels(tmp_path / "labels")
    box = np.zeros((24, 32), np.uint8)
    box[4:11, 4:13] = 1                                    # cv2.fillPoly of the rectangle: x 4..12, y 4..10
    (tmp_path / "pred" / "frame_00001").mkdir(parents=True)
    Image.fromarray(box).save(tmp_path / "pred" / "frame_00001" / "box.png")
    res = score_mask_folder(tmp_path / "pred", labels, "lerf")
    assert res["metrics"]["miou_lerf"] == 1.0
    Image.fromarray(np.ones((1, 1), np.uint8)).save(tmp_path / "pred" / "frame_00001" / "box.png")
    with pytest.raises(InputError, match=r"box\.png: prediction size 1x1 is too small"):
        score_mask_folder(tmp_path / "pred", labels, "lerf")


def test_not_an_image_is_refused(tmp_path):
    gt = _layout(tmp_path / "scene")
    _predict(tmp_path / "pred", gt, _as([0, 255], np.uint8))
    (tmp_path / "pred" / "0" / "a.png").write_text("not a picture")
    with pytest.raises(InputError, match=r"a\.png: not an image file"):
        score_mask_folder(tmp_path / "pred", tmp_path / "scene", "3dovs")


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES, ids=[h.name for h in CASES])
def test_hostile_eval_battery(case):
    """Each hostile:eval case through the real CLI (gsbench.commands.hostile.run_hostile)."""
    r = run_hostile(case)
    assert r.passed, r.note
