"""Every image reader applies the EXIF orientation: the header size and the decoded pixels are the
picture as a viewer shows it (PIL's ImageOps.exif_transpose is the reference), so a camera whose size
comes from the header (transforms.json without w/h) fits the pixels training reads."""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image, ImageOps

from gsbench.datasets.imageio import EXIF_ORIENTATION, image_size, read_gray, read_rgb

STORED = (np.random.default_rng(3).random((6, 10, 3)) * 255).astype(np.uint8)   # 10 wide, 6 high


def _png(path, pixels: np.ndarray, orientation: int) -> None:
    im = Image.fromarray(pixels)
    exif = Image.Exif()
    exif[EXIF_ORIENTATION] = orientation
    im.save(path, format="PNG", exif=exif.tobytes())


@pytest.mark.parametrize("orientation", range(1, 9))
def test_pixels_and_size_are_those_a_viewer_shows(tmp_path, orientation):
    p = tmp_path / "x.png"
    _png(p, STORED, orientation)
    with Image.open(p) as im:
        want = np.asarray(ImageOps.exif_transpose(im).convert("RGB"))
    assert image_size(p) == (want.shape[1], want.shape[0])
    got = read_rgb(p)
    np.testing.assert_array_equal(np.round(got * 255).astype(np.uint8), want)
    assert read_gray(p).shape == want.shape[:2]


def test_orientation_6_jpeg_reads_upright(tmp_path):
    """A phone's JPEG: stored 6 high x 10 wide, tag 6 (turn a quarter clockwise to show it)."""
    p = tmp_path / "x.jpg"
    exif = Image.Exif()
    exif[EXIF_ORIENTATION] = 6
    Image.fromarray(STORED).save(p, format="JPEG", quality=100, exif=exif.tobytes())
    assert image_size(p) == (6, 10)
    assert read_rgb(p).shape == (10, 6, 3)
    assert read_rgb(p, expect_size=(6, 10)).shape == (10, 6, 3)
    with pytest.raises(Exception, match="image is 6x10, camera says 10x6"):
        read_rgb(p, expect_size=(10, 6))


def test_an_orientation_outside_1_to_8_is_ignored(tmp_path):
    p = tmp_path / "x.png"
    _png(p, STORED, 0)
    assert image_size(p) == (10, 6) and read_rgb(p).shape == (6, 10, 3)
