"""Ordering metrics: adjacent camera distance and depth-warped adjacent mask IoU (hand cases)."""
from __future__ import annotations

import numpy as np
import pytest

from gsbench.camera import Camera
from gsbench.errors import InputError
from gsbench.metrics import adjacent_mask_iou, adjacent_mask_iou_pairs, mean_adjacent_distance

K = np.array([[10.0, 0, 8], [0, 10.0, 6], [0, 0, 1]])
H, W = 12, 16


def _w2c(center_x):
    w2c = np.eye(4)
    w2c[0, 3] = -center_x            # identity rotation: t = -R c
    return w2c


def test_mean_adjacent_distance_hand():
    c = np.array([[0, 0, 0], [1, 0, 0], [3, 0, 0], [6, 0, 0]], float)
    assert mean_adjacent_distance(c, [0, 1, 2, 3]) == pytest.approx(2.0)
    assert mean_adjacent_distance(c, [3, 0, 1, 2]) == pytest.approx((6 + 1 + 2) / 3)
    assert mean_adjacent_distance(np.array([[0, 0, 0], [3, 4, 0]]), [1, 0]) == pytest.approx(5.0)
    assert mean_adjacent_distance(c, [2]) is None
    with pytest.raises(InputError):
        mean_adjacent_distance(c, [0, 0, 1])
    with pytest.raises(InputError):
        mean_adjacent_distance(c, [0, 4])


def _labels(cols_by_id):
    m = np.full((H, W), -1, np.int32)
    for k, (c0, c1) in cols_by_id.items():
        m[:, c0:c1] = k
    return m


def test_adjacent_mask_iou_plane_shift_hand():
    # Plane at z = 2, second camera 0.4 to the right: every pixel moves 10 * 0.4 / 2 = 2 px left.
    depth = np.full((H, W), 2.0)
    cams = [(K, _w2c(0.0)), Camera(K, _w2c(0.4), W, H)]
    a = _labels({0: (4, 8), 1: (10, 14)})
    consistent = _labels({0: (2, 6), 1: (8, 12)})
    assert adjacent_mask_iou([a, consistent], [depth, depth], cams) == pytest.approx(1.0)
    # not propagated (ids stay where they were in the image): each id overlaps 2 of 6 columns
    assert adjacent_mask_iou([a, a], [depth, depth], cams) == pytest.approx(1 / 3)


def test_adjacent_mask_iou_uncovered_and_excluded():
    depth = np.full((H, W), 2.0)
    cams = [(K, _w2c(0.0)), (K, _w2c(0.4))]
    a = _labels({0: (4, 8), 2: (0, 2)})             # id 2 leaves the view after the shift
    b = _labels({0: (2, 6), 2: (14, 16)})           # id 2 appears in the uncovered strip
    pairs = adjacent_mask_iou_pairs([a, b], [depth, depth], cams)
    assert pairs[0]["ious"] == {0: pytest.approx(1.0)}
    assert pairs[0]["n_excluded"] == 1
    assert pairs[0]["covered_fraction"] == pytest.approx(14 / 16)


def test_occluded_points_are_dropped():
    cams = [(K, _w2c(0.0)), (K, _w2c(0.4))]
    a = _labels({0: (4, 8)})
    # frame b sees a surface at z = 1 everywhere: frame a's points (z = 2) are hidden behind it
    assert adjacent_mask_iou([a, a], [np.full((H, W), 2.0), np.full((H, W), 1.0)], cams) is None
    # within the 5 % tolerance they are kept
    assert adjacent_mask_iou([a, _labels({0: (2, 6)})], [np.full((H, W), 2.0), np.full((H, W), 1.95)],
                             cams) == pytest.approx(1.0)


def test_z_buffer_keeps_nearest():
    # Same camera for both frames, so the warp is the identity: nothing changes, IoU 1.
    rng = np.random.default_rng(0)
    m = rng.integers(-1, 4, size=(H, W)).astype(np.int32)
    d = rng.uniform(1, 5, size=(H, W))
    d[0, 0] = np.nan                                 # invalid depth: that pixel is not splatted
    cams = [(K, _w2c(0.0)), (K, _w2c(0.0))]
    assert adjacent_mask_iou([m, m], [d, d], cams) == pytest.approx(1.0)
    # Two source pixels land on one target pixel: the camera moves back by 2 (the image shrinks
    # by half), even columns carry id 0, odd columns id 1, and the target has no depth (no
    # occlusion test). Whichever id is nearer must fill every covered pixel.
    ids = np.where(np.arange(W)[None, :] % 2 == 0, 0, 1).repeat(H, 0).astype(np.int32)
    w2c = np.eye(4)
    w2c[2, 3] = 2.0                                  # camera centre at z = -2
    no_depth = np.full((H, W), np.nan)
    for even_z, winner in ((1.9, 0), (2.1, 1)):
        d = np.full((H, W), 2.0)
        d[:, ::2] = even_z
        target = np.full((H, W), winner, np.int32)
        pairs = adjacent_mask_iou_pairs([ids, target], [d, no_depth], [(K, np.eye(4)), (K, w2c)])
        assert pairs[0]["ious"] == {winner: pytest.approx(1.0)}, even_z


def test_bad_input():
    d = np.ones((H, W))
    m = np.zeros((H, W), np.int32)
    with pytest.raises(InputError):
        adjacent_mask_iou([m, m], [d], [(K, np.eye(4))] * 2)
    with pytest.raises(InputError):
        adjacent_mask_iou([m, m.astype(float)], [d, d], [(K, np.eye(4))] * 2)
    with pytest.raises(InputError):
        adjacent_mask_iou([m, m], [d, d], [(K, np.eye(4)), "camera"])
    assert adjacent_mask_iou([m], [d], [(K, np.eye(4))]) is None


# ------------------------------------------------------------------ strict and flow variants
from gsbench.metrics.ordering import adjacent_mask_iou_flow, adjacent_mask_iou_strict  # noqa: E402


def test_strict_counts_new_tracks_as_misses_hand():
    depth = np.full((H, W), 2.0)
    cams = [(K, _w2c(0.0)), (K, _w2c(0.4))]
    a = _labels({0: (4, 8), 1: (10, 14)})
    # frame b: object 1 got a new id 7 (a re-seeded track): lenient ignores it, strict scores 0 for 1 and 7
    b = _labels({0: (2, 6), 7: (8, 12)})
    assert adjacent_mask_iou([a, b], [depth, depth], cams) == pytest.approx(1.0)
    assert adjacent_mask_iou_strict([a, b], [depth, depth], cams) == pytest.approx(1 / 3)
    consistent = _labels({0: (2, 6), 1: (8, 12)})
    assert adjacent_mask_iou_strict([a, consistent], [depth, depth], cams) == pytest.approx(1.0)
    empty = np.full((H, W), -1, np.int32)
    assert adjacent_mask_iou_strict([empty, empty], [depth, depth], cams) is None


def _stripes(shift):
    x = np.arange(64)[None, :] - shift
    img = 0.5 + 0.4 * np.sin(x / 3.0) * np.cos(np.arange(48)[:, None] / 4.0)
    return np.repeat(img[..., None], 3, axis=2)


def test_flow_variant_follows_motion_and_counts_misses():
    # a textured image moved 2 px right: ids moved with it score high, ids left in place score lower
    a_img, b_img = _stripes(0), _stripes(2)
    m = np.full((48, 64), -1, np.int32)
    m[8:40, 8:28] = 0
    m[8:40, 34:56] = 1
    moved = np.roll(m, 2, axis=1)
    good = adjacent_mask_iou_flow([m, moved], [a_img, b_img])
    still = adjacent_mask_iou_flow([m, m], [a_img, b_img])
    assert good > 0.85 and good > still
    renamed = np.where(moved == 1, 5, moved)
    assert adjacent_mask_iou_flow([m, renamed], [a_img, b_img]) < 0.6 * good
    with pytest.raises(InputError, match="images"):
        adjacent_mask_iou_flow([m, m], [a_img])
