"""`lift`, the training-free lifting baseline: blending weights worked by hand on one-pixel cameras, the
weighted mean of the mask features, the top-k option, unseen Gaussians, and one run through train and eval."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from render_fields import look_at, random_field

from gsbench.camera import Camera
from gsbench.gaussians import GaussianField
from gsbench.methods.lift import lift_features, pixel_top_k, weights_by_backward, weights_top_k

BACKENDS = ("cpu", "torch")


def _logit(o: float) -> float:
    return float(np.log(o / (1.0 - o)))


def _field(means, opacities) -> GaussianField:
    """Small round Gaussians (scale 0.05) at `means` with the given activated opacities."""
    n = len(means)
    return GaussianField(torch.tensor(means, dtype=torch.float32), torch.full((n, 3), -3.0),
                         torch.tensor([[1.0, 0.0, 0.0, 0.0]] * n), torch.tensor([_logit(o) for o in opacities]),
                         torch.full((n, 3), 0.5))


def _camera(W: int = 1, H: int = 1, w2c=None) -> Camera:
    """Pinhole camera, principal point at the image centre: a point on its axis lands on (W/2, H/2)."""
    f = 0.9 * W
    return Camera(np.array([[f, 0, W / 2], [0, f, H / 2], [0, 0, 1.0]]), np.eye(4) if w2c is None else w2c, W, H)


def _back_camera() -> Camera:
    """At (0, 0, 4) looking down -z (a half turn about y): world z = 3 is 1 in front of it, z = 2 is 2."""
    w2c = np.diag([-1.0, 1.0, -1.0, 1.0])
    w2c[2, 3] = 4.0
    return _camera(w2c=w2c)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


F_A, F_B = _unit([1.0, 2.0, 0.0, 0.0]), _unit([0.0, 0.0, 3.0, 1.0])


@pytest.mark.parametrize("backend", BACKENDS)
def test_two_gaussians_on_one_pixel_weigh_alpha_times_transmittance(backend):
    # front opacity 0.6 at z=1, back 0.5 at z=2, both centred on the pixel (power 0, alpha = opacity):
    # w_front = 0.6, w_back = 0.5 * (1 - 0.6) = 0.2
    fld = _field([[0, 0, 1.0], [0, 0, 2.0]], [0.6, 0.5])
    a = weights_by_backward(fld, _camera(), torch.zeros(1, 1, dtype=torch.long), 1, backend)
    assert a[:, 0].tolist() == pytest.approx([0.6, 0.2], abs=1e-6)
    w, gid = pixel_top_k(fld, _camera(), 2)
    assert gid.tolist() == [[0, 1]] and w[0].tolist() == pytest.approx([0.6, 0.2], abs=1e-6)


def test_a_pixel_without_a_feature_adds_no_weight():
    fld = _field([[0, 0, 1.0]], [0.7])
    a = weights_by_backward(fld, _camera(), torch.full((1, 1), -1, dtype=torch.long), 1, "cpu")
    assert float(a.abs().sum()) == 0.0


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_weighted_mean_over_views_by_hand(backend):
    # g (opacity 0.8, z = 2) is alone in front of the origin camera (weight 0.8, pixel feature F_A); the
    # back camera sees the occluder (opacity 0.5, z = 3) first, so g weighs 0.8 * 0.5 = 0.4 there (F_B):
    # F_g = (0.8 F_A + 0.4 F_B) / 1.2 = (2 F_A + F_B) / 3
    fld = _field([[0, 0, 2.0], [0, 0, 3.0]], [0.8, 0.5])
    cams = {0: _camera(), 1: _back_camera()}
    masks = {0: np.array([[5]]), 1: np.array([[7]])}
    feats = {(0, 5): F_A, (1, 7): F_B}
    out, stats = lift_features(fld, cams, masks, feats, backend)
    assert out[0].double().numpy() == pytest.approx((2 * F_A + F_B) / 3, abs=1e-6)
    # the occluder: 0.5 * (1 - 0.8) = 0.1 of F_A from the origin camera, 0.5 of F_B from the back one
    assert out[1].double().numpy() == pytest.approx((0.1 * F_A + 0.5 * F_B) / 0.6, abs=1e-6)
    assert stats["lifted_gaussians"] == 2 and stats["unseen_gaussians"] == 0


def test_a_gaussian_seen_only_by_pixels_of_one_feature_gets_exactly_it_and_a_shared_one_the_mean():
    # a 6x1 image: pixels 0-2 mask 1 (F_A), pixels 3-5 mask 2 (F_B). Gaussian 0 (z = 4) is tiny and sits on
    # pixel 0's centre: the render's low-pass widens it to about 0.55 px, so it reaches pixels 0-1 only.
    # Gaussian 1 (z = 1, in front of everything) sits exactly between pixels 2 and 3, so its weights are
    # mirror images about x = 3 and it gets (F_A + F_B) / 2
    cam = _camera(6, 1)
    x_left = (0.5 - 3.0) / 5.4 * 4.0          # image x = 0.5 at depth 4 (f = 5.4, cx = 3)
    fld = _field([[x_left, 0, 4.0], [0, 0, 1.0]], [0.9, 0.3])
    fld = GaussianField(fld.means, torch.tensor([[-7.0] * 3, [-1.0] * 3]), fld.quats, fld.opacity_logits, fld.colors)
    masks = {0: np.array([[1, 1, 1, 2, 2, 2]])}
    out, _ = lift_features(fld, {0: cam}, masks, {(0, 1): F_A, (0, 2): F_B}, "cpu")
    assert out[0].double().numpy() == pytest.approx(F_A, abs=1e-6)
    assert out[1].double().numpy() == pytest.approx((F_A + F_B) / 2, abs=1e-6)


def test_top_k_one_keeps_only_the_front_gaussian():
    fld = _field([[0, 0, 1.0], [0, 0, 2.0]], [0.6, 0.5])
    cams, masks, feats = {0: _camera()}, {0: np.array([[3]])}, {(0, 3): F_A}
    every, _ = lift_features(fld, cams, masks, feats, "cpu")
    assert every[1].double().numpy() == pytest.approx(F_A, abs=1e-6)      # without top-k both get F_A
    front, stats = lift_features(fld, cams, masks, feats, "cpu", top_k=1)
    assert front[0].double().numpy() == pytest.approx(F_A, abs=1e-6)
    assert front[1].abs().sum().item() == 0.0                              # weight 0.2 is not the pixel's top 1
    assert stats["unseen_gaussians"] == 1 and stats["top_k"] == 1


def test_a_gaussian_no_pixel_sees_gets_the_zero_feature():
    # Gaussian 1 is behind the camera: no weight anywhere, so the zero vector (no direction, no class)
    fld = _field([[0, 0, 1.0], [0, 0, -2.0]], [0.6, 0.9])
    out, stats = lift_features(fld, {0: _camera()}, {0: np.array([[0]])}, {(0, 0): F_B}, "cpu")
    assert torch.isfinite(out).all() and out[1].abs().sum().item() == 0.0
    assert out[0].double().numpy() == pytest.approx(F_B, abs=1e-6)
    assert stats["unseen_gaussians"] == 1


def test_top_k_at_least_the_field_size_equals_the_backward_weights():
    fld = random_field(40, 3, d=0, dtype=torch.float32).with_features(None)
    cam = look_at(20, 14, eye=(0.3, 0.2, -3.0))
    rng = np.random.default_rng(0)
    index = torch.as_tensor(rng.integers(-1, 3, size=(14, 20)))
    a = weights_by_backward(fld, cam, index, 3, "torch")
    b = weights_top_k(fld, cam, index, 3, 40)
    assert float(a.abs().sum()) > 0.5
    assert b.numpy() == pytest.approx(a.numpy(), abs=1e-5)


def test_lift_trains_and_answers_queries_in_2d_and_3d(tmp_path):
    from gsbench.config import load_config
    from gsbench.datasets.synthetic import make_scene
    from gsbench.evaluation import evaluate_run
    from gsbench.runs import train_run
    from gsbench.store import read_json
    scene = make_scene("tabletop-small", tmp_path / "s", seed=0, views=8, resolution=(32, 24))
    tiny = ["backend=cpu", "train.iterations=12", "train.max_width=32", "train.eval_every=0",
            "train.checkpoint_every=0", "train.eval_views=1", "train.densify.enabled=false",
            "train.init.max_points=300"]
    run = train_run(load_config("lift", "cpu-small", tiny), scene, tmp_path / "lift", progress=False)
    info = read_json(run / "train_summary.json")["info"]
    assert info["budget"] == {"rgb_steps": 12, "semantic_steps": 0, "schedule": "lifted after rgb"}
    assert info["lift"]["lifted_gaussians"] > 0
    res = evaluate_run(run, protocol="3dovs,lerf,3d-points", progress=False)
    m = res["metrics"]
    for k in ("miou_3dovs", "mbiou_3dovs", "miou_lerf", "miou_3d", "macc_3d"):
        assert m[k] is not None and 0.0 <= m[k] <= 1.0, k
    assert m["miou_3dovs_encode"] == m["miou_3dovs_decode"]      # one space for both query modes


def test_a_scene_without_semantics_turns_the_lifting_off_with_the_reason(monkeypatch):
    from gsbench.config import load_config
    from gsbench.methods import lift_spec
    monkeypatch.setattr(lift_spec, "semantic_source", lambda cfg, scene: (False, "the scene has no labels"))
    cfg = load_config("lift", "cpu-small")
    dropped: dict = {}
    lift_spec.resolve(cfg, None, lambda part, why: dropped.setdefault(part, why))
    assert cfg["lift"]["semantics"] is False
    assert dropped["lift.semantics"] == dropped["priors.masks"] == "the scene has no labels"
    assert lift_spec.uses(cfg) == {"depth_prior": False, "semantics": False}
    assert lift_spec.budget(cfg)["schedule"] == "none"
