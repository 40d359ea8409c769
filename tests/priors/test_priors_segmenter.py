"""The SAM-like weight-free segmenter: each failure knob does what it says; severity 0 = GT."""
from __future__ import annotations

import numpy as np
import pytest
from partitions import same_partition
from sphere_scene import make_sphere_scene

from gsbench.errors import InputError
from gsbench.priors import prepare_priors
from gsbench.priors import segmenter as S


def rng(s=0):
    return np.random.default_rng(s)


def blocks():
    """Three touching rectangles and one small square on a background (-1)."""
    lab = np.full((40, 60), -1, np.int64)
    lab[5:35, 0:20] = 0
    lab[5:35, 20:40] = 1
    lab[5:35, 40:60] = 2
    lab[0:3, 0:3] = 3                                   # 9 px: a small object
    return lab


def n_segments(seg):
    return len(np.unique(seg[seg >= 0]))


def test_all_knobs_zero_is_the_gt_partition():
    lab = blocks()
    seg = S.segment_view(lab, S.SegmenterKnobs(), rng(), np.zeros((40, 60, 3)), np.ones((40, 60)))
    assert seg.dtype == np.int32 and same_partition(seg, lab)
    assert S.SegmenterKnobs.from_config({"severity": 0}).is_zero()


def test_merge_joins_touching_objects_only():
    lab = blocks()
    seg = S.segment_view(lab, S.SegmenterKnobs(merge=100), rng())
    # p = 1: each object merges with a touching neighbour -> the three blocks become one segment
    assert n_segments(seg[5:35]) == 1
    # the small square touches nothing: it stays alone
    assert seg[0, 0] >= 0 and seg[0, 0] != seg[20, 10]


def test_split_cuts_objects_into_parts():
    lab = blocks()
    seg = S.segment_view(lab, S.SegmenterKnobs(split=100), rng())
    for c0 in (0, 20, 40):
        assert n_segments(seg[5:35, c0:c0 + 20]) == 2
    assert (seg >= 0).sum() == (lab >= 0).sum()          # no pixel lost


def test_miss_drops_small_objects_and_keeps_large():
    lab = blocks()
    seg = S.segment_view(lab, S.SegmenterKnobs(miss=3), rng())
    # limit 0.004 * 3 * [0.5, 1.5] * 2400 px = 7..43 px: the 9 px square is missed only sometimes
    missed = [S.segment_view(lab, S.SegmenterKnobs(miss=3), rng(s))[0, 0] < 0 for s in range(20)]
    assert any(missed)
    seg = S.segment_view(lab, S.SegmenterKnobs(miss=10), rng())
    assert seg[0, 0] == -1 and n_segments(seg) == 3


def moved(seg, lab):
    """Pixels whose segment's majority GT label is not their own GT label."""
    out = np.zeros(lab.shape, bool)
    for sid in np.unique(seg[seg >= 0]):
        m = seg == sid
        vals, cnt = np.unique(lab[m], return_counts=True)
        out |= m & (lab != vals[np.argmax(cnt)])
    return out | ((seg < 0) != (lab < 0))


def test_leak_crosses_depth_edges_only():
    from scipy import ndimage
    lab = blocks()
    depth = np.ones((40, 60))
    depth[5:35, 20:40] = 2.0                               # block 1 is behind everything around it
    edge = ndimage.binary_dilation(lab == 1, iterations=3) & ~ndimage.binary_erosion(lab == 1, iterations=3)
    total = 0
    for s in range(6):
        mv = moved(S.segment_view(lab, S.SegmenterKnobs(leak=3), rng(s), depth=depth), lab)
        assert not (mv & ~edge).any()                      # leaks stay at block 1's depth edge (2 px)
        total += int(mv.sum())
    assert total > 0
    flat = np.ones((40, 60))
    for s in range(6):                                     # no depth discontinuity: nothing leaks
        assert same_partition(S.segment_view(lab, S.SegmenterKnobs(leak=3), rng(s), depth=flat), lab)


def test_texture_edges_cut_objects_but_not_flat_ones():
    lab = np.zeros((40, 60), np.int64)
    img = np.zeros((40, 60, 3), np.float32)
    img[:, 30:] = 1.0                                      # a texture edge inside the single object
    seg = S.segment_view(lab, S.SegmenterKnobs(texture=100), rng(), img)
    assert n_segments(seg) == 2 and seg[20, 5] != seg[20, 55]
    flat = S.segment_view(lab, S.SegmenterKnobs(texture=100), rng(), np.zeros_like(img))
    assert n_segments(flat) == 1
    with pytest.raises(InputError, match="texture failure needs"):
        S.segment_view(lab, S.SegmenterKnobs(texture=1), rng(), None)


def test_seeded_and_knobs_validated():
    lab = blocks()
    k = S.SegmenterKnobs(2, 2, 2, 2, 0)
    assert np.array_equal(S.segment_view(lab, k, rng(3)), S.segment_view(lab, k, rng(3)))
    assert (S.SegmenterKnobs.from_config({"severity": 2, "failures": {"merge": 0.5}})
            == S.SegmenterKnobs(0.5, 2, 2, 2, 2))
    with pytest.raises(InputError, match="priors.masks.failures"):
        S.SegmenterKnobs.from_config({"failures": {"blur": 1}})
    with pytest.raises(InputError, match="must be >= 0"):
        S.SegmenterKnobs.from_config({"severity": -1})


def test_every_knob_is_in_the_provider_id_and_the_cache_key(tmp_path):
    scene = make_sphere_scene(3, 48, 36, arc_deg=20.0, heights=(1.5,))
    base = {"provider": "simulated", "severity": 1}
    seen_ids, seen_keys = set(), set()
    for cfg in [base] + [dict(base, failures={f: 2}) for f in S.FAILURES]:
        p = prepare_priors(scene, {"masks": cfg}, [0, 1, 2], (48, 36), tmp_path, False, True, False, progress=False)
        seen_ids.add(p.providers["masks"])
        seen_keys.add(p.cache["masks"]["key"])
    assert len(seen_ids) == len(seen_keys) == 1 + len(S.FAILURES)


def test_severity_grows_disagreement_with_gt():
    scene = make_sphere_scene(2, 96, 72)
    inst = scene.gt_instances(1)
    img, depth = scene.image(1), scene.gt_depth(1)

    def wrong(seg):
        w = 0
        for s in np.unique(seg[seg >= 0]):
            _, cnt = np.unique(inst[seg == s], return_counts=True)
            w += cnt.sum() - cnt.max()
        return (w + np.sum((seg < 0) != (inst < 0)) + abs(n_segments(seg) - n_segments(inst)) * 50) / inst.size

    d = [np.mean([wrong(S.segment_view(inst, S.SegmenterKnobs(*(5 * [sev])), rng(s), img, depth))
                  for s in range(6)]) for sev in (0, 1, 3)]
    assert d[0] == 0 and d[0] < d[1] < d[2]
