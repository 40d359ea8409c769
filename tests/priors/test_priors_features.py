"""Feature providers: the weight-free text-aligned table, masked crops, missing OpenCLIP weights."""
from __future__ import annotations

import numpy as np
import pytest
from sphere_scene import CLASS_NAMES, make_sphere_scene

from gsbench.errors import InputError
from gsbench.priors import CANONICAL_NEGATIVES, get_feature_provider, prepare_priors
from gsbench.priors import features as F


def test_text_vectors_unit_stateless_and_normalised_names():
    a = get_feature_provider({"provider": "text-aligned"})
    b = get_feature_provider({"provider": "text-aligned"})
    t = a.encode_text(["mug", "  Mug ", "ball", "object"])
    assert t.shape == (4, 512) and t.dtype == np.float32
    assert np.allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-6)
    assert np.array_equal(t[0], t[1])                      # case / whitespace do not matter
    assert np.array_equal(t, b.encode_text(["mug", "mug", "ball", "object"]))
    assert a.canonical_negatives == CANONICAL_NEGATIVES == ("object", "things", "stuff", "texture")


def test_gt_mask_features_match_their_class_text_best():
    scene = make_sphere_scene(2, 64, 48)
    p = prepare_priors(scene, {"masks": {"provider": "gt"}, "features": {"provider": "text-aligned"}},
                       [0, 1], (64, 48), None, False, False, True, seed=0, progress=False)
    assert p.providers["features"] == "text-aligned-clipsim-v2"
    text = p.feature_provider.encode_text(CLASS_NAMES)
    for (_v, t), f in p.mask_features.items():
        assert f.shape == (512,) and abs(np.linalg.norm(f) - 1) < 1e-5
        cls = scene.instance_classes.get(t)
        if cls is None:
            continue
        assert int(np.argmax(text @ f)) == cls
    # one object, two views: different crops, different vectors (as CLIP)
    assert not np.array_equal(p.mask_features[(0, 0)], p.mask_features[(1, 0)])


def test_mask_shares_mix_inside_and_context():
    scene = make_sphere_scene(1, 8, 4)
    cls = np.array([[0, 0, 0, 1, 1, -1, -1, -1]] * 4, dtype=np.int32)
    scene.classes_loader = lambda i: cls
    labels = np.array([[5, 5, 5, 5, 5, 6, 6, 6]] * 4, dtype=np.int32)
    # no context: the pixel shares of the mask
    sh = F.TextAlignedFeatures(0.0, 0.0).mask_shares(scene, 0, labels)
    assert sh[5] == pytest.approx({CLASS_NAMES[0]: 0.6, CLASS_NAMES[1]: 0.4})
    assert sh[6] == pytest.approx({F.UNLABELLED: 1.0})
    # context 0.5: mask 6's ring (its box grown by half its width: columns 4..7 minus the mask) is class 1
    sh = F.TextAlignedFeatures(0.0, 0.5).mask_shares(scene, 0, labels)
    assert sh[6] == pytest.approx({F.UNLABELLED: 0.5, CLASS_NAMES[1]: 0.5})
    # a merged mask gets a blended vector: between the two pure ones
    f = F.TextAlignedFeatures(0.0, 0.0).encode_masks(scene, 0, None, labels)
    pure0 = F.TextAlignedFeatures(0.0, 0.0).encode_masks(scene, 0, None, np.where(cls == 0, 5, -1))[5]
    pure1 = F.TextAlignedFeatures(0.0, 0.0).encode_masks(scene, 0, None, np.where(cls == 1, 5, -1))[5]
    assert f[5] @ pure0 < 1 - 1e-4 and f[5] @ pure1 < 1 - 1e-4
    assert f[5] @ pure0 > pure1 @ pure0 and f[5] @ pure1 > pure1 @ pure0


def test_noise_knob_moves_features_and_is_seeded():
    scene = make_sphere_scene(1, 32, 24)
    labels = scene.gt_instances(0)
    clean = F.TextAlignedFeatures(0.0, 0.0).encode_masks(scene, 0, None, labels)
    noisy = F.TextAlignedFeatures(0.4, 0.0).encode_masks(scene, 0, None, labels, seed=1)
    again = F.TextAlignedFeatures(0.4, 0.0).encode_masks(scene, 0, None, labels, seed=1)
    other = F.TextAlignedFeatures(0.4, 0.0).encode_masks(scene, 0, None, labels, seed=2)
    for i in clean:
        assert np.array_equal(noisy[i], again[i]) and not np.array_equal(noisy[i], other[i])
        assert 0.8 < float(noisy[i] @ clean[i]) < 0.99
    with pytest.raises(InputError, match="priors.features.context"):
        get_feature_provider({"provider": "text-aligned", "context": 1.5})


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
    shares = F.TextAlignedFeatures().mask_shares(scene, 0, labels)
    scene.classes_loader = classes
    assert shares == F.TextAlignedFeatures().mask_shares(scene, 0, labels)


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


def test_feature_knobs_change_the_cache_key_and_per_track_means(tmp_path):
    scene = make_sphere_scene(4, 48, 36, arc_deg=30.0, heights=(1.5,))
    views = [0, 1, 2, 3]
    keys = set()
    for f in ({}, {"noise": 0.2}, {"context": 0.3}):
        p = prepare_priors(scene, {"masks": {"provider": "simulated", "severity": 0, "propagator": "reproject"},
                                   "features": dict(provider="text-aligned", **f)},
                           views, (48, 36), tmp_path, False, True, True, progress=False)
        keys.add(p.cache["features"]["key"])
    assert len(keys) == 3
    q = prepare_priors(scene, {"masks": {"provider": "simulated", "severity": 0, "propagator": "reproject"},
                               "features": {"provider": "text-aligned", "per_track": True}},
                       views, (48, 36), tmp_path, False, True, True, progress=False)
    assert q.providers["features"].endswith("+track-mean")
    by_track: dict = {}
    for (_, t), vec in q.mask_features.items():
        by_track.setdefault(t, []).append(vec)
    multi = [vs for vs in by_track.values() if len(vs) > 1]
    assert multi and all(np.array_equal(vs[0], w) for vs in multi for w in vs)
    assert all(abs(np.linalg.norm(vs[0]) - 1) < 1e-5 for vs in multi)
    # the track mean lies between the per-view features: closer to each than they are to each other
    base = prepare_priors(scene, {"masks": {"provider": "simulated", "severity": 0, "propagator": "reproject"},
                                  "features": {"provider": "text-aligned"}},
                          views, (48, 36), tmp_path, False, True, True, progress=False)
    t = next(t for t, vs in by_track.items() if len(vs) > 1)
    per_view = [base.mask_features[k] for k in sorted(base.mask_features) if k[1] == t]
    assert len(per_view) > 1 and not np.array_equal(per_view[0], per_view[1])
    assert by_track[t][0] @ per_view[0] >= per_view[0] @ per_view[1] - 1e-6
    r = prepare_priors(scene, {"masks": {"provider": "simulated", "severity": 0},
                               "features": {"provider": "text-aligned", "per_track": True}},
                       views, (48, 36), None, False, True, True, per_frame_masks=True, progress=False)
    assert "features.per_track" in r.skipped and not r.providers["features"].endswith("+track-mean")
