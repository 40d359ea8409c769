"""Feature providers: the weight-free text-aligned table, masked crops, missing OpenCLIP weights."""
from __future__ import annotations

import hashlib

import numpy as np
import pytest

from gsbench.errors import InputError
from gsbench.priors import CANONICAL_NEGATIVES, get_feature_provider, prepare_priors
from gsbench.priors import features as F
from tests.test_priors_scene import CLASS_NAMES, make_sphere_scene


def test_name_vectors_unit_stateless_and_distinct():
    a = get_feature_provider({"provider": "text-aligned", "noise": 0.05})
    b = get_feature_provider({"provider": "text-aligned", "noise": 0.05})
    t = a.encode_text(["mug", "  Mug ", "ball", "object"])
    assert t.shape == (4, 512) and t.dtype == np.float32
    assert np.allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-6)
    assert np.array_equal(t[0], t[1])                      # case / whitespace do not matter
    assert np.array_equal(t, b.encode_text(["mug", "mug", "ball", "object"]))
    assert abs(float(t[0] @ t[2])) < 0.25                   # random 512-d directions: near orthogonal
    # the vector is a function of sha256(name) only: reproduce it independently
    seed = int.from_bytes(hashlib.sha256(b"gsbench-text-aligned-v1:mug").digest()[:8], "little")
    ref = np.random.default_rng(seed).standard_normal(512)
    assert np.allclose(t[0], ref / np.linalg.norm(ref), atol=1e-6)
    assert a.canonical_negatives == CANONICAL_NEGATIVES == ("object", "things", "stuff", "texture")
    neg = a.encode_text(list(CANONICAL_NEGATIVES))
    assert np.abs(neg @ a.encode_text(["mug", "ball"]).T).max() < 0.25


def test_mask_features_follow_majority_class_with_noise():
    scene = make_sphere_scene(2, 64, 48)
    p = prepare_priors(scene, {"masks": {"provider": "gt"}, "features": {"provider": "text-aligned", "noise": 0.05}},
                       [0, 1], (64, 48), None, False, False, True, seed=0, progress=False)
    assert p.providers["features"] == "text-aligned-sim-v1"
    fp = p.feature_provider
    text = fp.encode_text(CLASS_NAMES)
    for (_v, t), f in p.mask_features.items():
        assert f.shape == (512,) and abs(np.linalg.norm(f) - 1) < 1e-5
        cls = scene.instance_classes[t]                     # gt masks: track id = instance id
        sims = text @ f
        assert int(np.argmax(sims)) == cls
        # noise with expected norm 0.05 around a unit vector: cosine ~ 1 / sqrt(1 + 0.05^2)
        assert 0.99 < sims[cls] < 1.0
    # noise is per mask: the same class in two views gives different vectors
    assert not np.array_equal(p.mask_features[(0, 4)], p.mask_features[(1, 4)])


def test_majority_class_vote():
    scene = make_sphere_scene(1, 8, 4)
    cls = np.array([[0, 0, 0, 1, 1, -1, -1, -1]] * 4, dtype=np.int32)
    scene.classes_loader = lambda i: cls
    labels = np.array([[5, 5, 5, 5, 5, 6, 6, 6]] * 4, dtype=np.int32)
    names = F.TextAlignedFeatures(0.0).mask_classes(scene, 0, labels)
    assert names == {5: CLASS_NAMES[0], 6: F.UNLABELLED}
    feats = F.TextAlignedFeatures(0.0).encode_masks(scene, 0, None, labels)
    assert np.allclose(feats[5], F.name_vector(CLASS_NAMES[0]))


def test_text_aligned_needs_gt_classes():
    scene = make_sphere_scene(1, 8, 4)
    scene.classes_loader = None
    scene.instances_loader = None
    with pytest.raises(InputError, match="text-aligned needs GT classes"):
        F.TextAlignedFeatures().encode_masks(scene, 0, None, np.zeros((4, 8), np.int32))


def test_instances_plus_instance_classes_suffice():
    scene = make_sphere_scene(1, 32, 24)
    classes = scene.classes_loader
    scene.classes_loader = None
    labels = scene.gt_instances(0)
    names = F.TextAlignedFeatures().mask_classes(scene, 0, labels)
    scene.classes_loader = classes
    assert names == F.TextAlignedFeatures().mask_classes(scene, 0, labels)


def test_masked_square_crop_hand_computed():
    img = np.arange(4 * 6 * 3, dtype=np.float32).reshape(4, 6, 3) / 100
    m = np.zeros((4, 6), bool)
    m[1, 1:5] = True
    m[2, 2] = True
    c = F.masked_square_crop(img, m)
    # bbox rows 1..2, cols 1..4 -> 2 x 4 crop, padded to 4 x 4 (one black row above and below)
    assert c.shape == (4, 4, 3)
    assert np.all(c[0] == 0) and np.all(c[3] == 0)
    assert np.allclose(c[1], img[1, 1:5])
    assert np.allclose(c[2, 1], img[2, 2]) and np.all(c[2, [0, 2, 3]] == 0)   # background blacked out
    assert F.masked_square_crop(img, np.zeros((4, 6), bool)) is None


def test_openclip_missing_weights_one_line_error(tmp_path):
    missing = tmp_path / "open_clip_vit_b16.bin"
    with pytest.raises(InputError) as e:
        get_feature_provider({"provider": "openclip", "checkpoint": str(missing)})
    msg = str(e.value)
    assert "\n" not in msg and "priors.features.checkpoint" in msg and str(missing) in msg
    assert "priors.features.provider=openclip" in msg
    with pytest.raises(InputError, match="priors.features.checkpoint: not set"):
        get_feature_provider({"provider": "openclip"})
    with pytest.raises(InputError, match="priors.features.provider"):
        get_feature_provider({"provider": "dino"})
    with pytest.raises(InputError, match="priors.features.noise"):
        get_feature_provider({"provider": "text-aligned", "noise": -1})
