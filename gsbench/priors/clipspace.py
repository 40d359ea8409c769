"""A weight-free text/image embedding space with CLIP's geometry.

The LERF protocol (relevancy = softmax at temperature 10 against the canonical negatives,
threshold 0.5) was designed for CLIP, whose embeddings sit in a narrow cone with a gap between
the image and the text side. A table of random orthogonal vectors breaks it: any positive cosine
beats an orthogonal negative. This space reproduces the geometry instead. With fixed unit axes
c_t (text centre), c_i (image centre, cos(c_t, c_i) = RHO) and a seeded unit direction u_n per
normalised name, orthogonal to both centres:

* text of a noun:           t_n = ALPHA c_t + BETA u_n
* text of a canonical negative ("object", "things", "stuff", "texture"): the same with NEG_ALPHA,
  so negatives sit closer to every noun than nouns sit to each other;
* image of a pure class k:  x_k = GAMMA c_i + DELTA u_k + STYLE s_k + NOISE n,
  s_k a per-class image-only direction, n per-mask noise (`gsbench.priors.features`).

Expected cosines (the numbers real CLIP ViT-B/16 gives on typical nouns and crops):
text-text between unrelated nouns ALPHA^2 = 0.75; noun-negative ALPHA NEG_ALPHA = 0.82;
matching image-text GAMMA ALPHA RHO + DELTA BETA = 0.30; non-matching GAMMA ALPHA RHO = 0.20;
image-negative GAMMA NEG_ALPHA RHO = 0.22. So a matching mask has relevancy
sigmoid(10 (0.30 - 0.22)) = 0.69 > 0.5 and a non-matching one sigmoid(-0.2) = 0.45 < 0.5.
Tests check these statistics on generated vectors.
"""
from __future__ import annotations

import hashlib

import numpy as np

DIM = 512
SPACE_VERSION = 1
ALPHA = float(np.sqrt(0.75))
BETA = float(np.sqrt(1.0 - 0.75))
NEG_ALPHA = 0.95
GAMMA = 0.8
DELTA = 0.2
RHO = 0.2 / (GAMMA * ALPHA)
STYLE = 0.4
CANONICAL_NEGATIVES = ("object", "things", "stuff", "texture")
BACKGROUND = "<unlabelled>"


def normalise_name(name: str) -> str:
    return " ".join(str(name).strip().lower().split())


def _rng(*parts) -> np.random.Generator:
    h = hashlib.sha256(":".join(str(p) for p in parts).encode("utf-8")).digest()
    return np.random.default_rng(int.from_bytes(h[:8], "little"))


def _axes() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(c_t, c_i, Q): the two unit centres and an orthonormal basis Q (DIM x 2) of their span."""
    q, _ = np.linalg.qr(_rng("gsbench-clipspace-axes", SPACE_VERSION).standard_normal((DIM, 2)))
    e0, e1 = q[:, 0], q[:, 1]
    c_t = e0
    c_i = RHO * e0 + np.sqrt(1.0 - RHO ** 2) * e1
    return c_t, c_i, q


_C_T, _C_I, _Q = _axes()


def unit(x: np.ndarray) -> np.ndarray:
    """Rows of `x` divided by their norm (float64); a zero row is an error, not a silent NaN."""
    x = np.asarray(x, dtype=np.float64)
    n = np.linalg.norm(x, axis=-1, keepdims=True)
    if np.any(n <= 1e-12):
        raise ValueError("cannot normalise a zero vector")
    return x / n


def random_direction(*parts) -> np.ndarray:
    """A seeded unit vector orthogonal to both centres (the span of c_t, c_i)."""
    v = _rng("gsbench-clipspace-dir", SPACE_VERSION, *parts).standard_normal(DIM)
    v -= _Q @ (_Q.T @ v)
    return unit(v)


def concept(name: str) -> np.ndarray:
    """u_n: the name's shared (text and image) direction."""
    return random_direction("concept", normalise_name(name))


def style(name: str) -> np.ndarray:
    """s_k: the image-only appearance direction of class `name`."""
    return random_direction("style", normalise_name(name))


def text_vector(name: str) -> np.ndarray:
    """Unit text embedding of `name` (canonical negatives sit closer to the centre)."""
    n = normalise_name(name)
    a = NEG_ALPHA if n in CANONICAL_NEGATIVES else ALPHA
    return unit(a * _C_T + np.sqrt(1.0 - a * a) * concept(n)).astype(np.float32)


def image_vector(weights: dict[str, float], noise: float, noise_dir: np.ndarray) -> np.ndarray:
    """Unit image embedding of a crop showing the classes in `weights` (name -> share, sums to 1).

    The concept and style parts are the share-weighted mix, so a crop covering two objects gets
    a blended vector; `noise` scales the per-crop direction `noise_dir`.
    """
    mix = np.zeros(DIM)
    for name, w in weights.items():
        mix += float(w) * (DELTA * concept(name) + STYLE * style(name))
    return unit(GAMMA * _C_I + mix + float(noise) * np.asarray(noise_dir, dtype=np.float64)).astype(np.float32)
