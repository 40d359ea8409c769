"""The 3d-points protocol: labelled surface points of a synthetic scene (exact, seeded, nothing written to the
scene) and its scores end to end on fields built by hand, with answers worked from the point counts."""
from __future__ import annotations

import hashlib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from gsbench.camera import Camera
from gsbench.datasets import load_scene
from gsbench.datasets.loader import scene_fingerprint
from gsbench.datasets.surface_points import surface_points
from gsbench.datasets.synthetic_spec import WALL_Y, compose
from gsbench.errors import InputError
from gsbench.evaluation.points3d_protocol import OPACITY_FLOOR, POINT_COUNT, POINT_SEED
from gsbench.evaluation.protocol_registry import ProtocolContext, get_protocol
from gsbench.gaussians import GaussianField


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory) -> Path:
    from gsbench.datasets.synthetic import make_scene
    return make_scene("tabletop-small", tmp_path_factory.mktemp("p3") / "scene", seed=0, views=6, resolution=(32, 24))


@pytest.fixture(scope="module")
def scene(scene_dir):
    return load_scene(scene_dir)


def score_points3d(method, scene, mode: str):
    """The registered protocol's Block for one query mode (the configured one)."""
    protocol = get_protocol("3d-points")
    return protocol.score(ProtocolContext(protocol=protocol, method=method, scene=scene, config={}, sets={},
                                          modes=(mode,), configured=mode))


def _tree_digest(root: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        if p.is_file():
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def test_points_lie_on_the_analytic_surfaces_with_their_labels(scene):
    pts, lab, names = surface_points(scene, 3000, 0)
    assert 0.9 * 3000 <= len(pts) <= 3000 and lab.shape == (len(pts),)
    assert set(np.unique(lab)) >= {names.index("floor"), names.index("wall")}
    floor, wall = lab == names.index("floor"), lab == names.index("wall")
    assert np.abs(pts[floor, 2]).max() < 1e-9
    assert np.abs(pts[wall, 1] - WALL_Y).max() < 1e-9
    spec = compose("tabletop-small", 0, 6, (32, 24))
    for p in spec.prims:
        if p.kind == "sphere" and names.index(p.name) in lab:
            d = np.linalg.norm(pts[lab == names.index(p.name)] - p.center, axis=1)
            assert np.abs(d - p.size[0]).max() < 1e-9, p.name


def test_points_are_seeded(scene):
    a, la, _ = surface_points(scene, 500, 4)
    b, lb, _ = surface_points(scene, 500, 4)
    c, _, _ = surface_points(scene, 500, 5)
    assert np.array_equal(a, b) and np.array_equal(la, lb)
    assert not np.array_equal(a[:50], c[:50])


def test_scoring_writes_nothing_into_the_scene(scene_dir):
    before, fp = _tree_digest(scene_dir), scene_fingerprint(scene_dir)
    s = load_scene(scene_dir)
    surface_points(s, 1000, 0)
    score_points3d(_OneHot(s, *_points(s)), s, "encode")
    assert _tree_digest(scene_dir) == before and scene_fingerprint(scene_dir) == fp


def test_an_edited_camera_is_refused(scene_dir):
    s = load_scene(scene_dir)
    c = s.cameras[2]
    w2c = c.world_to_camera.copy()
    w2c[0, 3] += 0.01
    s.cameras[2] = Camera(c.K, w2c, c.width, c.height, name=c.name)
    with pytest.raises(InputError, match="camera 2 differs"):
        surface_points(s, 100, 0)
    out = score_points3d(_OneHot(s, *_points(load_scene(scene_dir))), s, "encode")
    assert out.metrics["miou_3d"] is None and "camera 2 differs" in out.skipped["miou_3d"]


# ---------------------------------------------------------------------------- hand-built fields
def _points(scene):
    """The protocol's own points and labels (its count and seed)."""
    pts, lab, _ = surface_points(scene, POINT_COUNT, POINT_SEED)
    return pts, lab


class _OneHot:
    """A 'trained' method built by hand: one Gaussian on each scored point, whose feature is the one-hot of
    `classes` (its class index), the class texts one-hot too; `opacity` per Gaussian."""

    name = "hand"

    def __init__(self, scene, means, classes, opacity=None):
        n, c = len(means), len(scene.class_names)
        op = np.full(n, 0.9) if opacity is None else np.asarray(opacity, dtype=np.float64)
        self.c = c
        self.feats = torch.nn.functional.one_hot(torch.as_tensor(classes), c).float()
        self.field = GaussianField(torch.as_tensor(means, dtype=torch.float32), torch.zeros(n, 3),
                                   torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
                                   torch.as_tensor(np.log(op / (1 - op)), dtype=torch.float32), torch.zeros(n, 3))

    def gaussian_semantic_features(self, mode):
        return self.feats

    def embed_text(self, texts, mode):
        return torch.eye(self.c)


def test_gaussians_with_the_true_classes_score_one(scene):
    pts, lab = _points(scene)
    out = score_points3d(_OneHot(scene, pts, lab), scene, "decode")
    assert out.metrics == {"miou_3d": 1.0, "macc_3d": 1.0, "miou_3d_decode": 1.0, "macc_3d_decode": 1.0}
    assert out.metric_impl["miou_3d"].endswith("+query-decode") and "nearest" in out.metric_impl["miou_3d"]


def test_every_gaussian_called_wall(scene):
    # every point predicted wall: IoU_wall = n_wall / n, every other class 0; Acc_wall = 1, others 0
    pts, lab = _points(scene)
    wall = list(scene.class_names).index("wall")
    out = score_points3d(_OneHot(scene, pts, np.full(len(lab), wall)), scene, "encode")
    present = len(np.unique(lab))
    assert out.metrics["miou_3d"] == pytest.approx(np.count_nonzero(lab == wall) / len(lab) / present)
    assert out.metrics["macc_3d"] == pytest.approx(1.0 / present)


def test_faint_gaussians_are_ignored(scene):
    # the floor's Gaussians below the opacity floor: no floor point can be called floor (Acc 0), every other
    # point still finds its own Gaussian at distance 0 (Acc 1): mAcc = (present - 1) / present
    pts, lab = _points(scene)
    floor = list(scene.class_names).index("floor")
    op = np.where(lab == floor, OPACITY_FLOOR / 2, 0.9)
    out = score_points3d(_OneHot(scene, pts, lab, op), scene, "encode")
    present = len(np.unique(lab))
    assert out.metrics["macc_3d"] == pytest.approx((present - 1) / present)
    assert out.metrics["miou_3d"] < out.metrics["macc_3d"]
    at_floor = score_points3d(_OneHot(scene, pts, lab, np.full(len(lab), OPACITY_FLOOR)), scene, "encode")
    assert at_floor.metrics["miou_3d"] == 1.0       # strictly below the floor is ignored, at it is not


def test_a_method_without_per_gaussian_semantics_is_skipped_with_the_reason(scene):
    from gsbench.methods.vanilla import Vanilla
    v = Vanilla()
    pts, _ = _points(scene)
    v.field = _OneHot(scene, pts[:10], np.zeros(10, dtype=np.int64)).field
    out = score_points3d(v, scene, "encode")
    assert out.metrics == {"miou_3d": None, "macc_3d": None, "miou_3d_encode": None, "macc_3d_encode": None}
    assert out.skipped["miou_3d"] == "method vanilla has no per-Gaussian semantic features in this run"


def test_a_scene_without_an_analytic_surface_is_skipped(scene):
    pts, lab = _points(scene)
    real = SimpleNamespace(meta={}, path="captures/room", class_names=list(scene.class_names))
    out = score_points3d(_OneHot(scene, pts, lab), real, "encode")
    assert out.metrics["macc_3d"] is None and "no analytic surface" in out.skipped["macc_3d"]


def test_a_floor_of_exact_zeros_under_flushed_denormals_scores_and_keeps_the_flag():
    # `import gsbench` flushes denormals; with that on, scipy's cKDTree crashed the process on 12,000 of
    # 20,000 centres sharing z = 0 exactly. point_classes turns flushing off for the tree and back on after
    from gsbench.metrics.points3d import point_classes
    assert float((np.array([1e-310]) * np.float64(1.0))[0]) == 0.0       # gsbench's setting is on
    means = np.random.default_rng(0).random((20000, 3))
    means[:12000, 2] = 0.0
    cls = (np.arange(20000) % 3).astype(np.int64)
    got = point_classes(means[:50], means, cls)
    assert got.tolist() == cls[:50].tolist()                             # each point is its own nearest
    assert float((np.array([1e-310]) * np.float64(1.0))[0]) == 0.0       # and the setting is back
