"""IoU, boundary band and Boundary IoU: hand-computed cases, a direct definition, properties."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gsbench.errors import InputError
from gsbench.metrics import boundary_band, boundary_iou, boundary_width, iou, mbiou, miou


def _square(h, w, r0, r1, c0, c1):
    m = np.zeros((h, w), bool)
    m[r0:r1, c0:c1] = True
    return m


def test_iou_hand():
    p = np.array([[1, 1, 0], [0, 0, 0]])
    g = np.array([[0, 1, 1], [0, 0, 0]])
    assert iou(p, g) == pytest.approx(1 / 3)
    assert iou(p, p) == 1.0
    assert iou(p, np.array([[0, 0, 1], [1, 1, 1]])) == 0.0


def test_iou_empty_union_is_defined():
    z = np.zeros((3, 3), bool)
    assert iou(z, z) == 1.0
    assert iou(z, z, empty=0.0) == 0.0
    # empty prediction against a non-empty GT is a plain 0, not the empty rule
    assert iou(z, _square(3, 3, 0, 1, 0, 1), empty=1.0) == 0.0


def test_iou_bad_input():
    with pytest.raises(InputError):
        iou(np.zeros((3, 3)), np.zeros((3, 4)))
    with pytest.raises(InputError):
        iou(np.zeros((3, 3, 1)), np.zeros((3, 3, 1)))


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 12), st.integers(1, 12), st.integers(0, 2 ** 31 - 1))
def test_iou_properties(h, w, seed):
    rng = np.random.default_rng(seed)
    a, b = rng.random((h, w)) < 0.5, rng.random((h, w)) < 0.5
    assert iou(a, b) == iou(b, a)
    assert 0.0 <= iou(a, b) <= 1.0
    if a.any():
        assert iou(a, a) == 1.0
        assert iou(a, ~a) == 0.0
    perm = rng.permutation(h * w)                 # IoU ignores where the pixels are
    assert iou(a.reshape(-1)[perm].reshape(h, w), b.reshape(-1)[perm].reshape(h, w)) == iou(a, b)


def test_boundary_width_hand():
    assert boundary_width(100, 100) == 3           # 0.02 * 141.4 = 2.83
    assert boundary_width(10, 10) == 1             # 0.28 -> at least 1
    assert boundary_width(480, 640) == 16          # 0.02 * 800
    assert boundary_width(100, 100, 0.05) == 7     # 7.07


def test_boundary_band_hand():
    full = np.ones((5, 5), bool)                   # only the image border bounds it
    band = boundary_band(full, width=1)
    expect = np.ones((5, 5), bool)
    expect[1:4, 1:4] = False
    np.testing.assert_array_equal(band, expect)
    sq = _square(7, 7, 2, 5, 2, 5)                 # 3x3 square in the middle
    band = boundary_band(sq, width=1)
    expect = sq.copy()
    expect[3, 3] = False
    np.testing.assert_array_equal(band, expect)
    assert not boundary_band(np.zeros((6, 6), bool), width=2).any()


def _band_direct(m, d):
    """Mask pixels within Chebyshev distance d of a background pixel or of the image border."""
    h, w = m.shape
    bg = np.argwhere(~m)
    out = np.zeros_like(m)
    for i, j in np.argwhere(m):
        border = min(i + 1, j + 1, h - i, w - j)
        dist = border
        if len(bg):
            dist = min(dist, int(np.max(np.abs(bg - [i, j]), axis=1).min()))
        out[i, j] = dist <= d
    return out


@pytest.mark.parametrize("seed", range(8))
def test_boundary_band_matches_direct_definition(seed):
    rng = np.random.default_rng(seed)
    h, w = rng.integers(5, 30, size=2)
    # blobby masks: thresholded smoothed noise, plus pure noise for seed 0
    noise = rng.random((h, w))
    if seed:
        k = np.ones((3, 3)) / 9
        from scipy.signal import convolve2d
        noise = convolve2d(noise, k, mode="same", boundary="symm")
    m = noise > np.quantile(noise, rng.uniform(0.2, 0.8))
    for d in (1, 2, 3, boundary_width(h, w)):
        np.testing.assert_array_equal(boundary_band(m, width=d), _band_direct(m, d))
    np.testing.assert_array_equal(boundary_band(m), _band_direct(m, boundary_width(h, w)))


def test_boundary_iou_hand():
    # 10x10 image -> d = 1. A 6x6 square and the same square shifted right by one column.
    g = _square(10, 10, 2, 8, 2, 8)
    p = _square(10, 10, 2, 8, 3, 9)
    # rings of 20 pixels each sharing rows 2 and 7 on columns 3..7 (10 pixels): 10 / 30
    assert boundary_iou(p, g) == pytest.approx(1 / 3)
    assert iou(p, g) == pytest.approx(30 / 42)
    assert boundary_iou(p, g, coco_min=True) == pytest.approx(1 / 3)
    assert boundary_iou(p, p) == 1.0
    assert boundary_iou(p, _square(10, 10, 0, 1, 0, 1)) == 0.0
    assert boundary_iou(p, g) == boundary_iou(g, p)


def test_boundary_iou_empty():
    z = np.zeros((6, 6), bool)
    assert boundary_iou(z, z) == 1.0
    assert boundary_iou(z, z, empty=0.0) == 0.0


def test_boundary_iou_coco_min_takes_iou_when_lower():
    # two big overlapping squares whose bands coincide better than their areas? no: use a case
    # where IoU < BIoU: thin masks are all band, so BIoU == IoU; a big mask with a small
    # prediction inside touching the same border.
    g = _square(40, 40, 0, 40, 0, 40)              # whole image, band = frame of width d=1
    p = _square(40, 40, 0, 40, 0, 2)               # 2 columns on the left
    b = boundary_iou(p, g)
    i = iou(p, g)
    assert i == pytest.approx(80 / 1600)
    assert b > i
    assert boundary_iou(p, g, coco_min=True) == pytest.approx(i)


def test_means_refuse_missing_values():
    assert miou([0.5, 1.0]) == 0.75
    assert mbiou([]) is None
    with pytest.raises(InputError):
        miou([0.5, None])
    with pytest.raises(InputError):
        mbiou([float("nan")])
