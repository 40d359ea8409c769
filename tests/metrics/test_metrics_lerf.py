"""LERF-OVS protocol: relevancy, blend, threshold, LangSplat smoothing, level selection, scene."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from gsbench.errors import InputError

from gsbench.metrics import (LerfPair, box_mean, evaluate_lerf_scene, lerf_blend, lerf_localization,  # isort: skip
                             lerf_mask, lerf_relevancy, majority_smooth)


def test_relevancy_hand():
    f = np.array([[[1.0, 0.0], [0.0, 3.0], [0.0, 0.0]]])            # (1, 3, 2); last pixel has no feature
    t = np.array([2.0, 0.0])                                          # not unit: normalised inside
    negs = np.array([[0.0, 1.0], [1.0, 0.0]])
    r = lerf_relevancy(f, t, negs)
    # pixel 0: vs n1 softmax(10*[1, 0]) = 1/(1+e^-10); vs n2 softmax(10*[1, 1]) = 0.5 -> min 0.5
    # pixel 1: vs n1 1/(1+e^10); vs n2 0.5 -> 1/(1+e^10); pixel 2: zero feature -> 0.5
    np.testing.assert_allclose(r, [[0.5, 1 / (1 + math.exp(10)), 0.5]], rtol=1e-6)


def test_relevancy_matches_explicit_softmax():
    rng = np.random.default_rng(0)
    f = rng.standard_normal((5, 7, 16)).astype(np.float32)
    q = rng.standard_normal((3, 16))
    n = rng.standard_normal((4, 16))
    fu = torch.nn.functional.normalize(torch.from_numpy(f).double(), dim=-1)
    qu = torch.nn.functional.normalize(torch.from_numpy(q), dim=-1)
    nu = torch.nn.functional.normalize(torch.from_numpy(n), dim=-1)
    r = lerf_relevancy(f, q, n)
    assert r.shape == (3, 5, 7)
    for k in range(3):
        pos = (fu @ qu[k])[..., None].expand(5, 7, 4)
        neg = fu @ nu.T
        sm = torch.softmax(10 * torch.stack([pos, neg], -1), -1)[..., 0]
        np.testing.assert_allclose(r[k], sm.min(-1).values.numpy(), atol=1e-6)
        np.testing.assert_allclose(lerf_relevancy(f, q[k], n), r[k], atol=1e-6)  # float32 matmul


def test_min_over_negatives_before_the_sigmoid_is_the_min_of_the_sigmoids_bit_for_bit():
    """lerf_relevancy takes the largest negative cosine before one sigmoid per (pixel, query); the
    protocol's form is one sigmoid per negative, then the minimum. Written out here in float64 from
    the same cosines, the two must agree exactly, ties and saturated pixels included."""
    from gsbench.metrics import pixel_norms, pixel_text_cosines
    rng = np.random.default_rng(7)
    f = rng.standard_normal((40, 50, 8)).astype(np.float32)
    f[0, :5] = 0.0                                                    # no feature: cosine 0 with all
    q, n = rng.standard_normal((3, 8)), rng.standard_normal((4, 8))
    n[1] = n[0]                                                       # a tie among the negatives
    q[2] = 40 * n[2]                                                  # a query equal to a negative
    cos, _ = pixel_text_cosines(f, np.concatenate([q, n]), "f")
    for t in (10.0, 1e3, 0.25):
        z = t * (cos[:, :3, None] - cos[:, None, 3:])
        e = np.exp(-np.abs(z))
        old = np.where(z >= 0, 1.0 / (1.0 + e), e / (1.0 + e)).min(axis=2).T.reshape(3, 40, 50)
        np.testing.assert_array_equal(lerf_relevancy(f, q, n, temperature=t), old)
        np.testing.assert_array_equal(lerf_relevancy(f, q, n, temperature=t, pixel_norms=pixel_norms(f, "f")), old)
    z = -2.0 * (cos[:, :3, None] - cos[:, None, 3:])                 # t < 0: the minimum moves, the rule holds
    e = np.exp(-np.abs(z))
    old = np.where(z >= 0, 1.0 / (1.0 + e), e / (1.0 + e)).min(axis=2).T.reshape(3, 40, 50)
    np.testing.assert_array_equal(lerf_relevancy(f, q, n, temperature=-2.0), old)
    with pytest.raises(InputError, match="pixel norms"):
        lerf_relevancy(f, q, n, pixel_norms=np.ones(7))


def test_box_mean_window_and_blend():
    rng = np.random.default_rng(1)
    r = rng.random((50, 60))
    m = box_mean(r)
    # cv2's anchor for an even 30-tap kernel is 15: rows i-15 .. i+14
    assert m[25, 30] == pytest.approx(r[10:40, 15:45].mean(), abs=1e-12)
    np.testing.assert_allclose(lerf_blend(r), 0.5 * (r + m), atol=1e-15)
    np.testing.assert_allclose(box_mean(np.full((40, 40), 0.3)), 0.3, atol=1e-12)


def _smooth_langsplat_literal(mask):
    """LangSplat's `smooth`, read literally: bincount majority in a truncated 7x7 window."""
    h, w = mask.shape
    out = mask.copy()
    for i in range(h):
        for j in range(w):
            sq = mask[max(0, i - 3):min(i + 4, h - 1), max(0, j - 3):min(j + 4, w - 1)]
            out[i, j] = np.argmax(np.bincount(sq.reshape(-1), minlength=2))
    return out


def _smooth_centered_literal(mask):
    h, w = mask.shape
    out = mask.copy()
    for i in range(h):
        for j in range(w):
            sq = mask[max(0, i - 3):i + 4, max(0, j - 3):j + 4]
            out[i, j] = 2 * sq.sum() > sq.size
    return out


@pytest.mark.parametrize("seed", range(6))
def test_majority_smooth_matches_literal(seed):
    rng = np.random.default_rng(seed)
    h, w = rng.integers(2, 25, size=2)
    m = (rng.random((h, w)) < rng.uniform(0.3, 0.7)).astype(np.uint8)
    np.testing.assert_array_equal(majority_smooth(m), _smooth_langsplat_literal(m).astype(bool))
    np.testing.assert_array_equal(majority_smooth(m, window="centered"), _smooth_centered_literal(m).astype(bool))


def test_lerf_mask_threshold_and_smoothing_hand():
    r = np.full((16, 16), 0.2)
    r[5:10, 5:10] = 0.9            # x = 0.7 / 0.75 = 0.93 > 0.7: kept, then eroded by the vote
    r[12, 2] = 0.95                # the maximum, an isolated pixel: removed by the vote
    r[0:4, 9:16] = 0.7             # x = 0.5 / 0.75 = 0.67 < 0.7: below the threshold
    pred = lerf_mask(r)
    expect = np.zeros((16, 16), bool)
    expect[6:9, 6:9] = True        # 5x5 block: only pixels whose 7x7 window holds 5x5 = 25 > 24.5 ones
    np.testing.assert_array_equal(pred, expect)
    # with threshold 0.6 the slab (x = 0.67) passes; at (1, 12) the edge-truncated window is
    # rows 0..4 x cols 9..14 (30 pixels) holding 4 x 6 = 24 slab pixels, so it survives the vote
    pred2 = lerf_mask(r, threshold=0.6)
    assert pred2[1, 12] and not pred[0:4, 9:16].any()


def _block_map(h=64, w=64, lo=0.1, hi=0.9):
    r = np.full((h, w), lo)
    r[20:40, 20:40] = hi
    return r


def test_scene_protocol_hand():
    # Blend of the 20x20 block: r' >= 0.6 inside (corner), <= 0.28 outside, min 0.1, max 0.68,
    # so x > 0.7 selects exactly the block; the 7x7 vote then drops 5 pixels at each corner.
    lvl0 = _block_map()
    lvl1 = 0.5 + 0.2 * (_block_map()[::-1] - 0.5)          # weaker map elsewhere: not selected
    gt = np.zeros((64, 64), bool)
    gt[20:40, 20:40] = True
    gt_half = gt.copy()
    gt_half[30:40] = False
    pairs = [
        LerfPair("frame_00001", "mug", [lvl0, lvl1], gt, np.array([[20, 20, 39, 39]])),
        LerfPair("frame_00001", "plate", np.stack([lvl1, lvl0]), gt_half, np.array([[0, 0, 10, 10]])),
    ]
    res = evaluate_lerf_scene(pairs)
    assert [p["level"] for p in res.per_pair] == [0, 1]
    assert res.per_pair[0]["iou"] == pytest.approx(380 / 400)
    # GT = top half (200 px): intersection 200 - 2 corners x 5 = 190, union 380 + 200 - 190 = 390
    assert res.per_pair[1]["iou"] == pytest.approx(190 / 390)
    assert res.miou == pytest.approx((0.95 + 190 / 390) / 2)
    assert [p["localized"] for p in res.per_pair] == [True, False]
    assert res.loc_acc == 0.5 and res.n_loc == 2 and res.skipped == []


def test_localization_uses_raw_map_and_any_box():
    r = _block_map()
    assert lerf_localization([r], [[0, 0, 5, 5], [25, 25, 30, 30]])
    assert not lerf_localization([r], [[45, 45, 60, 60]])
    # a box given with swapped corners is the same box
    assert lerf_localization([r], [[30, 30, 25, 25]])


def test_missing_predictions_are_never_silently_dropped():
    gt = np.zeros((64, 64), bool)
    gt[20:40, 20:40] = True
    good = LerfPair("frame_00002", "mug", [_block_map()], gt, np.array([[20, 20, 39, 39]]))
    miss = LerfPair("frame_00003", "mug", None, gt, np.array([[20, 20, 39, 39]]))
    with pytest.raises(InputError, match="frame_00003"):
        evaluate_lerf_scene([good, miss])
    skip = evaluate_lerf_scene([good, miss], missing="skip")
    assert skip.miou == pytest.approx(0.95) and skip.n_iou == 1 and skip.n_pairs == 2
    assert skip.skipped == [{"frame": "frame_00003", "query": "mug", "reason": "missing prediction"}]
    zero = evaluate_lerf_scene([good, miss], missing="zero")
    assert zero.miou == pytest.approx(0.475) and zero.loc_acc == 0.5 and len(zero.skipped) == 1


def test_empty_gt_and_bad_input():
    """An empty GT mask is counted as LangSplat counts it: |P & G| / |P | G| = 0 for a non-empty
    prediction; both empty (0 / 0 in the reference) scores 1, as in `eval --masks`."""
    empty = LerfPair("f", "q", [_block_map()], np.zeros((64, 64), bool), np.array([[20, 20, 39, 39]]))
    res = evaluate_lerf_scene([empty])
    assert res.miou == 0.0 and res.n_iou == 1 and res.loc_acc == 1.0 and res.skipped == []
    assert res.per_pair[0]["empty_gt"] is True
    flat = LerfPair("f", "q", [np.full((64, 64), 0.4)], np.zeros((64, 64), bool))   # predicts nothing
    assert evaluate_lerf_scene([flat]).miou == 1.0
    no_mask = LerfPair("f", "q", [_block_map()], None, np.array([[20, 20, 39, 39]]))
    res = evaluate_lerf_scene([no_mask])
    assert res.miou is None and res.n_iou == 0 and res.skipped[0]["reason"] == "no GT mask"
    with pytest.raises(InputError, match="differ in size"):
        evaluate_lerf_scene([LerfPair("f", "q", [_block_map()], np.zeros((32, 32), bool))])
    with pytest.raises(InputError):
        evaluate_lerf_scene([LerfPair("f", "q", [_block_map()])])
    feats = np.ones((4, 4, 3), np.float32)
    feats[1, 2, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        lerf_relevancy(feats, np.ones(3), np.eye(3))
    with pytest.raises(InputError):
        lerf_relevancy(np.ones((4, 4, 3)), np.zeros(3), np.eye(3))     # zero query embedding
