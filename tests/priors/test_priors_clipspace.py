"""The weight-free text/image space has CLIP's geometry, and LERF relevancy behaves as with CLIP."""
from __future__ import annotations

import numpy as np

from gsbench.metrics.lerf import LERF_TEMPERATURE, lerf_relevancy
from gsbench.priors import clipspace as C
from gsbench.priors.features import TextAlignedFeatures

NOUNS = ["ball", "box", "can", "globe", "orange", "poster", "mug", "book", "brick", "candle", "teddy bear",
         "sofa", "lamp", "plant", "chair", "window"]


def image(name, seed, noise=0.4):
    return C.image_vector({name: 1.0}, noise, C.random_direction("test-noise", name, seed))


def offdiag(m):
    return m[~np.eye(len(m), dtype=bool)]


def test_text_text_cosines_sit_in_a_narrow_cone():
    t = np.stack([C.text_vector(n) for n in NOUNS]).astype(np.float64)
    assert np.allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-6)
    tt = offdiag(t @ t.T)
    assert 0.7 <= tt.mean() <= 0.8 and tt.min() > 0.6 and tt.max() < 0.9
    neg = np.stack([C.text_vector(n) for n in C.CANONICAL_NEGATIVES]).astype(np.float64)
    # canonical negatives are closer to every noun than nouns are to each other
    assert (t @ neg.T).min() > tt.mean()


def test_image_text_cosines_and_modality_gap():
    t = np.stack([C.text_vector(n) for n in NOUNS]).astype(np.float64)
    x = np.stack([image(n, s) for n in NOUNS for s in range(3)]).astype(np.float64)
    cls = np.repeat(np.arange(len(NOUNS)), 3)
    it = x @ t.T
    match = it[np.arange(len(x)), cls]
    non = np.array([it[i, j] for i in range(len(x)) for j in range(len(NOUNS)) if j != cls[i]])
    assert 0.25 <= match.mean() <= 0.35 and 0.15 <= non.mean() <= 0.25
    assert (match > non.max() - 0.05).mean() > 0.9
    # modality gap: the image cloud's centre is far from the text cloud's
    gap = float(C.unit(x.mean(0)) @ C.unit(t.mean(0)))
    assert gap < 0.4


def test_lerf_relevancy_matching_beats_negatives_non_matching_does_not():
    f = TextAlignedFeatures()
    neg = f.encode_text(list(C.CANONICAL_NEGATIVES))
    q = f.encode_text(NOUNS)
    x = np.stack([image(n, 7) for n in NOUNS])                       # one "pixel" per noun
    r = lerf_relevancy(x.reshape(len(NOUNS), 1, -1), q, neg, temperature=LERF_TEMPERATURE)  # (Q, N, 1)
    r = r[:, :, 0]
    diag = np.diag(r)
    off = offdiag(r)
    assert (diag > 0.5).all() and (off < 0.5).mean() > 0.95
    # the cosines of an orthogonal table would make every positive cosine relevant: not here
    assert off.max() < 0.55


def test_blended_feature_lowers_relevancy_of_each_class():
    f = TextAlignedFeatures()
    neg = f.encode_text(list(C.CANONICAL_NEGATIVES))
    q = f.encode_text(["ball", "box"])
    n = C.random_direction("test-blend")
    pure = C.image_vector({"ball": 1.0}, 0.4, n)
    mixed = C.image_vector({"ball": 0.5, "box": 0.5}, 0.4, n)
    r = lerf_relevancy(np.stack([pure, mixed]).reshape(2, 1, -1), q, neg)[:, :, 0]
    assert r[0, 0] > r[0, 1]                                        # ball query: the pure crop wins
    assert r[1, 1] > r[1, 0]                                        # box query: the mixed crop wins


def test_float64_reference_of_a_cosine():
    # the closed-form expectation of the matching cosine (module doc) without noise or style
    t = C.text_vector("ball").astype(np.float64)
    v = C.GAMMA * C._C_I + C.DELTA * C.concept("ball")
    expect = (C.GAMMA * C.ALPHA * C.RHO + C.DELTA * C.BETA) / np.linalg.norm(v)
    assert abs(float(t @ (v / np.linalg.norm(v))) - expect) < 1e-6


def test_pipeline_mask_features_pass_lerf_relevancy_like_clip():
    """GT masks at the default noise and context: the own class beats the negatives, others mostly do not."""
    from sphere_scene import CLASS_NAMES, make_sphere_scene

    from gsbench.priors import prepare_priors
    scene = make_sphere_scene(3, 64, 48)
    p = prepare_priors(scene, {"masks": {"provider": "gt"}, "features": {"provider": "text-aligned"}},
                       [0, 1, 2], (64, 48), None, False, False, True, progress=False)
    fp = p.feature_provider
    q, neg = fp.encode_text(CLASS_NAMES), fp.encode_text(list(fp.canonical_negatives))
    own, other = [], []
    for (_v, t), f in p.mask_features.items():
        cls = scene.instance_classes.get(t)
        if cls is None:
            continue
        r = lerf_relevancy(f.reshape(1, 1, -1), q, neg)[:, 0, 0]
        own.append(r[cls])
        other.extend(np.delete(r, cls))
    assert len(own) >= 6
    assert np.mean(np.array(own) > 0.5) == 1.0 and np.mean(np.array(other) < 0.5) > 0.9
