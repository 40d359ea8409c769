"""EXIF orientation in the evaluation's image readers (issue 51): a predicted mask of `eval --masks`
and a 3D-OVS GT mask stored sideways with orientation 6 are read as PIL's ImageOps.exif_transpose
shows them (size from the header and pixels alike), so an upright-equal prediction scores 1."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageOps

from gsbench.evaluation import score_mask_folder
from gsbench.evaluation.labels import read_mask
from gsbench.evaluation.mask_files import image_size, read_binary_mask, read_class_map

H, W = 16, 24       # displayed size; the files hold the pixels turned a quarter counter-clockwise
TURNED = 6          # EXIF: turn the stored pixels a quarter clockwise for display


def _save_sideways(path: Path, upright: np.ndarray, fmt: str = "PNG", **kw) -> None:
    """Store `upright` turned a quarter counter-clockwise with orientation 6, so that a viewer that
    applies EXIF shows `upright`."""
    exif = Image.Exif()
    exif[0x0112] = TURNED
    Image.fromarray(np.ascontiguousarray(np.rot90(upright, 1))).save(path, format=fmt, exif=exif, **kw)


def _as_viewer_shows(path: Path) -> np.ndarray:
    with Image.open(path) as im:
        return np.asarray(ImageOps.exif_transpose(im))


def _upright_mask() -> np.ndarray:
    m = np.zeros((H, W), bool)
    m[:8, :8] = True        # an asymmetric block: any wrong turn or mirror moves it
    return m


def test_binary_mask_png_with_orientation_6_is_read_upright(tmp_path):
    m = _upright_mask()
    p = tmp_path / "a.png"
    _save_sideways(p, m.astype(np.uint8) * 255)
    shown = _as_viewer_shows(p)
    assert shown.shape == (H, W)                       # the file itself is W x H the other way round
    assert image_size(p) == (W, H)
    np.testing.assert_array_equal(read_binary_mask(p), shown == 255)
    np.testing.assert_array_equal(read_binary_mask(p), m)


@pytest.mark.parametrize("value", range(1, 9))
def test_every_orientation_is_read_as_exif_transpose_shows_it(tmp_path, value):
    stored = _upright_mask()
    stored[0, :12] = True           # no turn or mirror of it equals another
    exif = Image.Exif()
    exif[0x0112] = value
    p = tmp_path / f"o{value}.png"
    Image.fromarray(stored.astype(np.uint8) * 255).save(p, format="PNG", exif=exif)
    shown = _as_viewer_shows(p) == 255
    assert image_size(p) == (shown.shape[1], shown.shape[0])
    np.testing.assert_array_equal(read_binary_mask(p), shown)
    np.testing.assert_array_equal(read_mask(p) == 255, shown)


def test_class_map_png_with_orientation_6_is_read_upright(tmp_path):
    idx = np.where(_upright_mask(), 1, 0).astype(np.uint8)
    idx[-1, -1] = 255
    p = tmp_path / "classes.png"
    _save_sideways(p, idx)
    read = read_class_map(p, 2)
    shown = _as_viewer_shows(p).astype(np.int32)
    np.testing.assert_array_equal(read, np.where(shown == 255, -1, shown))
    assert read[-1, -1] == -1 and read[0, 0] == 1 and read.shape == (H, W)


def test_jpeg_with_orientation_6_size_and_gt_pixels_match_exif_transpose(tmp_path):
    p = tmp_path / "a.jpg"
    _save_sideways(p, _upright_mask().astype(np.uint8) * 255, fmt="JPEG", quality=100)
    shown = _as_viewer_shows(p)
    assert image_size(p) == (shown.shape[1], shown.shape[0]) == (W, H)
    gt = read_mask(p)
    assert gt.shape == shown.shape
    assert np.abs(gt.astype(int) - shown.astype(int)).max() <= 8      # two JPEG decoders, same layout


def _scene(root: Path, gt: dict[str, np.ndarray], sideways_gt: bool) -> None:
    (root / "images").mkdir(parents=True)
    for k in range(2):
        Image.fromarray(np.zeros((H, W, 3), np.uint8)).save(root / "images" / f"img_{k}.png")
        (root / "segmentations" / str(k)).mkdir(parents=True)
        for c, m in gt.items():
            f = root / "segmentations" / str(k) / f"{c}.png"
            if sideways_gt:
                _save_sideways(f, m.astype(np.uint8) * 255)
            else:
                Image.fromarray(m.astype(np.uint8) * 255).save(f)
    (root / "segmentations" / "classes.txt").write_text("a\nb\n")


def _predictions(pred: Path, masks: dict[str, np.ndarray], sideways: bool) -> None:
    for k in range(2):
        (pred / str(k)).mkdir(parents=True)
        for c, m in masks.items():
            if sideways:
                _save_sideways(pred / str(k) / f"{c}.png", m.astype(np.uint8) * 255)
            else:
                Image.fromarray(m.astype(np.uint8) * 255).save(pred / str(k) / f"{c}.png")


@pytest.mark.parametrize("sideways_gt, sideways_pred", [(False, True), (True, False)])
def test_masks_stored_sideways_score_1_against_their_upright_twins(tmp_path, sideways_gt, sideways_pred):
    """Predictions stored sideways against upright GT, and GT stored sideways against upright predictions:
    without the orientation the 24x16 stored files would be refused (another aspect ratio)."""
    a = _upright_mask()
    gt = {"a": a, "b": ~a}
    _scene(tmp_path / "scene", gt, sideways_gt=sideways_gt)
    _predictions(tmp_path / "pred", gt, sideways=sideways_pred)
    res = score_mask_folder(tmp_path / "pred", tmp_path / "scene", "3dovs")
    assert res["metrics"]["miou_3dovs"] == 1.0
