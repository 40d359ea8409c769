"""Pseudo-video ordering: pose-nearest chain, random, filename; the ordering study's metrics."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from sphere_scene import make_sphere_scene

from gsbench.camera import Camera
from gsbench.errors import InputError
from gsbench.priors import ordering as O
from gsbench.priors import prepare_priors


def cams_at(centers, names=None):
    out = []
    for k, c in enumerate(centers):
        T = np.eye(4)
        T[:3, 3] = -np.asarray(c, float)          # identity rotation: centre = c
        out.append(Camera(np.diag([10.0, 10.0, 1.0]), T, 8, 8, name=(names[k] if names else f"c{k}")))
    return out


def test_camera_centres_round_trip():
    cams = cams_at([(1.0, 2.0, 3.0)])
    assert np.allclose(O.camera_centers(cams, [0]), [[1, 2, 3]])


def test_pose_order_recovers_a_shuffled_line():
    xs = [0.0, 1.0, 1.5, 4.0, 4.2, 7.0, 9.0, 9.5]
    perm = np.random.default_rng(3).permutation(len(xs))
    cams = cams_at([(xs[i], 0.0, 0.0) for i in perm])
    order = O.order_views(cams, list(range(len(cams))), "pose")
    got = [cams[v].center[0] for v in order]
    assert got == sorted(xs) or got == sorted(xs, reverse=True)
    # the path along a line visits each gap once: length = max - min
    assert O.path_length(O.camera_centers(cams, range(len(cams))), order) == pytest.approx(9.5)


def test_adjacent_distance_hand_computed():
    cams = cams_at([(0, 0, 0), (1, 0, 0), (3, 0, 0)])
    assert O.adjacent_distance(cams, [0, 1, 2]) == pytest.approx(1.5)      # (1 + 2) / 2
    assert O.adjacent_distance(cams, [1, 0, 2]) == pytest.approx(2.0)      # (1 + 3) / 2
    assert O.adjacent_distance(cams, [2]) is None


@pytest.mark.parametrize("seed", range(6))
def test_pose_order_no_worse_than_greedy_and_two_opt_optimal(seed):
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(25, 3))
    cams = cams_at(pts)
    order = O.order_views(cams, list(range(25)), "pose")
    assert sorted(order) == list(range(25))
    dist = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    start = int(np.unravel_index(np.argmax(dist), dist.shape)[0])
    # greedy nearest neighbour written out independently
    left, chain = set(range(25)) - {start}, [start]
    while left:
        nxt = min(left, key=lambda j: (dist[chain[-1], j], j))
        chain.append(nxt)
        left.remove(nxt)
    L = O.path_length(pts, order)
    assert L <= O.path_length(pts, chain) + 1e-9
    # local optimality: no single segment reversal (open path, ends included) shortens it
    for i in range(25):
        for j in range(i + 1, 25):
            alt = order[:i] + order[i:j + 1][::-1] + order[j + 1:]
            assert O.path_length(pts, alt) >= L - 1e-9


def test_pose_order_small_sets_near_optimal():
    # brute force over all open paths of 7 points: 2-opt is a heuristic (no bound is guaranteed),
    # but on these seeded sets it is close to the optimum on average and never far off
    rng = np.random.default_rng(11)
    ratios = []
    for _ in range(6):
        pts3 = np.c_[rng.uniform(size=(7, 2)), np.zeros(7)]
        best = min(O.path_length(pts3, p) for p in itertools.permutations(range(7)))
        order = O.order_views(cams_at(pts3), list(range(7)), "pose")
        ratios.append(O.path_length(pts3, order) / best)
    assert min(ratios) >= 1.0 - 1e-12
    assert np.mean(ratios) <= 1.05 and max(ratios) <= 1.2


def test_random_order_is_a_seeded_permutation():
    cams = cams_at(np.random.default_rng(0).normal(size=(30, 3)))
    ids = list(range(5, 25))
    a = O.order_views(cams, ids, "random", seed=1)
    b = O.order_views(cams, ids, "random", seed=1)
    c = O.order_views(cams, ids, "random", seed=2)
    assert a == b and a != c and sorted(a) == ids


def test_filename_order_is_natural():
    names = ["img10.png", "img2.png", "img1.png", "IMG3.png"]
    cams = cams_at([(k, 0, 0) for k in range(4)], names)
    order = O.order_views(cams, [0, 1, 2, 3], "filename")
    assert [names[v] for v in order] == ["img1.png", "img2.png", "IMG3.png", "img10.png"]


def test_unknown_ordering_and_duplicates():
    cams = cams_at([(0, 0, 0), (1, 0, 0)])
    with pytest.raises(ValueError, match="unknown ordering"):
        O.order_views(cams, [0, 1], "bogus")
    with pytest.raises(ValueError, match="duplicates"):
        O.order_views(cams, [0, 0], "pose")


def _ordering_figures(scene, views, size):
    out = {}
    for mode in ("pose", "filename", "random"):
        cfg = {"ordering": mode, "masks": {"provider": "simulated", "severity": 1, "propagator": "flow"}}
        p = prepare_priors(scene, cfg, views, size, None, need_depth=False, need_masks=True,
                           need_features=False, seed=0, progress=False)
        assert p.providers["ordering"] == mode and p.order != [] and sorted(p.order) == sorted(views)
        out[mode] = (p.stats["ordering_adjacent_distance"], p.stats["ordering_adjacent_mask_iou"])
    return out


def test_pose_order_beats_filename_and_random_on_ring_scene():
    # Two rings of cameras named in capture order: filename order jumps from the end of ring 1
    # back to the start of ring 2; pose order interleaves the rings.
    scene = make_sphere_scene(10, 96, 72)
    f = _ordering_figures(scene, list(range(len(scene.cameras))), (96, 72))
    assert f["pose"][0] < f["filename"][0] < f["random"][0]
    assert f["pose"][1] > f["random"][1] + 0.1


def test_pose_order_on_generated_tabletop(tmp_path):
    synthetic = pytest.importorskip("gsbench.datasets.synthetic")
    from gsbench.datasets import load_scene
    root = synthetic.make_scene("tabletop-small", tmp_path / "scene", seed=0)
    scene = load_scene(root)
    size = (scene.cameras[0].width, scene.cameras[0].height)
    f = _ordering_figures(scene, list(scene.train_ids), size)
    assert f["pose"][0] < f["random"][0]
    assert f["pose"][0] <= f["filename"][0] + 1e-12
    assert f["pose"][1] > f["random"][1] + 0.05


def test_prepare_priors_rejects_unknown_ordering():
    scene = make_sphere_scene(2, 16, 12)
    with pytest.raises(InputError, match="priors.ordering"):
        prepare_priors(scene, {"ordering": "zigzag"}, [0, 1], (16, 12), None, False, False, False, progress=False)


def _targets(p, v):
    """Per-pixel supervision target (the feature of the pixel's track; 0 where none)."""
    m = p.masks[v]
    out = np.zeros(m.shape + (512,), np.float32)
    for t in np.unique(m[m >= 0]):
        out[m == t] = p.mask_features[(v, int(t))]
    return out


def test_ordering_changes_the_supervision_and_strict_metric_ranks_it():
    scene = make_sphere_scene(10, 64, 48)
    views = list(range(len(scene.cameras)))
    cfg = {"masks": {"provider": "simulated", "severity": 1}}
    pr = {m: prepare_priors(scene, dict(cfg, ordering=m), views, (64, 48), None, False, True, True,
                            progress=False) for m in ("pose", "random")}
    differ = sum(int((np.abs(_targets(pr["pose"], v) - _targets(pr["random"], v)).max(-1) > 1e-6).sum())
                 for v in views)
    assert differ > 0
    s_pose, s_rand = pr["pose"].stats, pr["random"].stats
    # strict scores count new tracks as misses: never above the lenient score, and pose beats random
    for s in (s_pose, s_rand):
        assert s["ordering_adjacent_mask_iou_strict"] <= s["ordering_adjacent_mask_iou"] + 1e-12
    assert s_pose["ordering_adjacent_mask_iou_strict"] > s_rand["ordering_adjacent_mask_iou_strict"]
    assert s_pose["ordering_adjacent_mask_iou_flow"] > s_rand["ordering_adjacent_mask_iou_flow"]


def test_flow_metric_is_reported_without_gt_depth():
    scene = make_sphere_scene(4, 48, 36, arc_deg=30.0, heights=(1.5,))
    scene.depth_loader = None
    assert not scene.has_depth
    p = prepare_priors(scene, {"masks": {"provider": "simulated", "severity": 0}}, [0, 1, 2, 3], (48, 36), None,
                       False, True, False, progress=False)
    assert p.stats["ordering_adjacent_mask_iou"] is None and "ordering_adjacent_mask_iou" in p.skipped
    assert p.stats["ordering_adjacent_mask_iou_strict"] is None
    assert 0.0 < p.stats["ordering_adjacent_mask_iou_flow"] <= 1.0
