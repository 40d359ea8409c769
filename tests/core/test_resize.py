"""gsbench.resize: the one home of every resize. Nearest sampling equals PIL NEAREST (the 3D-OVS
reference) for every dtype; RGB equals PIL's bicubic on the 8-bit image (3DGS's loader)."""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from gsbench.errors import InputError
from gsbench.resize import resize_area, resize_nearest, resize_rgb


@pytest.mark.parametrize("seed", range(40))
def test_nearest_equals_pil_nearest_for_every_size_and_dtype(seed):
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(1, 120, 2))
    H, W = (int(v) for v in rng.integers(1, 120, 2))
    a = rng.integers(0, 255, (h, w)).astype(np.uint8)
    ref = np.asarray(Image.fromarray(a).resize((W, H), Image.Resampling.NEAREST))
    np.testing.assert_array_equal(resize_nearest(a, W, H), ref)
    # the same pick for dtypes PIL and OpenCV do not resize (labels as int64, masks as bool, depth as float)
    ids = a.astype(np.int64) * 1_000_003
    np.testing.assert_array_equal(resize_nearest(ids, W, H), ref.astype(np.int64) * 1_000_003)
    m = resize_nearest(a > 127, W, H)
    assert m.dtype == np.bool_ and np.array_equal(m, ref > 127)
    z = resize_nearest(a.astype(np.float32) / 7.0, W, H)
    np.testing.assert_array_equal(z, ref.astype(np.float32) / 7.0)


def test_rgb_equals_pil_bicubic_on_8_bits_and_drops_alpha():
    rng = np.random.default_rng(3)
    img = rng.random((30, 40, 4)).astype(np.float32)
    q = np.floor(np.clip(img[..., :3], 0, 1) * 255 + 0.5).astype(np.uint8)
    ref = np.asarray(Image.fromarray(q, "RGB").resize((17, 11), Image.Resampling.BICUBIC), np.float32) / 255.0
    np.testing.assert_array_equal(resize_rgb(img, 17, 11), ref)
    assert resize_rgb(img, 40, 30).shape == (30, 40, 3)


def test_same_size_comes_back_unchanged_and_bad_input_is_named():
    a = np.arange(12.0).reshape(3, 4)
    assert resize_nearest(a, 4, 3) is a and resize_area(a, 4, 3) is a
    with pytest.raises(InputError, match="resize_nearest"):
        resize_nearest(np.zeros((2, 2, 3)), 1, 1)
    with pytest.raises(InputError, match="resize_rgb"):
        resize_rgb(np.zeros((4, 4)), 2, 2)
