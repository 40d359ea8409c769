"""A weight-free per-frame segmenter that fails the way SAM's automatic masks fail.

GaussianDS exists because a per-frame segmenter does not cut the scene the same way in every
view. This model starts from the GT instance map of one view and applies five failures, each
with its own severity knob (a float >= 0; 0 switches it off), seeded by (seed, view):

* ``merge``: touching objects merged. Each instance joins a random touching neighbour with
  probability ``MERGE_P * merge * g`` (g: the view's granularity, below).
* ``split``: one object split into parts: each segment is cut by a random line through its
  centroid with probability ``SPLIT_P * split / g``.
* ``miss``: small objects missed: instances (and cut parts) smaller than ``MISS_AREA_FRAC *
  miss * g'`` of the image get no mask (-1); g' is uniform in [0.5, 1.5] per view.
* ``leak``: boundaries leak across depth discontinuities: half of the segments (chosen per view)
  grow by ``max(1, LEAK_DIAG_FRAC * leak * diagonal)`` pixels into neighbours whose depth differs
  by more than ``DEPTH_JUMP`` (relative); without depth, into any neighbour.
* ``texture``: texture-only edges taken as object edges: a segment is cut along the image's
  Canny edges that are not GT object edges, with probability ``TEXTURE_P * texture``.

Granularity: each view draws g = exp(N(0, GRANULARITY_SIGMA)); a coarse view (g > 1) merges
more and splits less, a fine view the opposite, so views disagree on what an object is.
Ids are permuted per view: they mean nothing across views before propagation. All knobs zero
gives the GT partition exactly (ids permuted).
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Mapping

import cv2
import numpy as np
from scipy import ndimage

from gsbench.config import check_key
from gsbench.errors import InputError

SEGMENTER_VERSION = 2
FAILURES = ("merge", "split", "miss", "leak", "texture")
MERGE_P = 0.15
SPLIT_P = 0.15
MISS_AREA_FRAC = 0.004
LEAK_DIAG_FRAC = 0.006
DEPTH_JUMP = 0.05
TEXTURE_P = 0.25
GRANULARITY_SIGMA = 0.5
CANNY_LOW, CANNY_HIGH = 40, 120


@dataclass(frozen=True)
class SegmenterKnobs:
    """Severity of each failure (>= 0). `from_config` fills unset knobs from `severity`."""

    merge: float = 0.0
    split: float = 0.0
    miss: float = 0.0
    leak: float = 0.0
    texture: float = 0.0

    @classmethod
    def from_config(cls, masks_cfg: Mapping) -> "SegmenterKnobs":
        sev = masks_cfg.get("severity", 1)
        failures = masks_cfg.get("failures") or {}
        if not isinstance(failures, Mapping):
            raise InputError(f"priors.masks.failures: expected a mapping of {', '.join(FAILURES)}, got {failures!r}")
        unknown = sorted(set(failures) - set(FAILURES))
        if unknown:
            raise InputError(f"priors.masks.failures: unknown failure(s) {unknown} (expected {', '.join(FAILURES)})")
        sev = check_key("priors.masks.severity", sev)
        return cls(**{f: float(check_key(f"priors.masks.failures.{f}", sev if failures.get(f) is None else failures[f]))
                      for f in FAILURES})

    def tag(self) -> str:
        """Compact id part, e.g. 'merge1-split1-miss1-leak1-texture1'."""
        return "-".join(f"{f.name}{getattr(self, f.name):g}" for f in fields(self))

    def is_zero(self) -> bool:
        return all(getattr(self, f) == 0 for f in FAILURES)


def neighbour_pairs(labels: np.ndarray) -> set[tuple[int, int]]:
    """Unordered pairs of labels (>= 0) that touch horizontally or vertically."""
    pairs = set()
    for a, b in ((labels[:, :-1], labels[:, 1:]), (labels[:-1, :], labels[1:, :])):
        m = (a != b) & (a >= 0) & (b >= 0)
        if m.any():
            for x, y in np.unique(np.stack([a[m], b[m]], 1), axis=0):
                pairs.add((int(min(x, y)), int(max(x, y))))
    return pairs


def label_edges(labels: np.ndarray) -> np.ndarray:
    """Bool map of pixels whose right or lower neighbour has another label (both sides marked)."""
    e = np.zeros(labels.shape, bool)
    dx = labels[:, 1:] != labels[:, :-1]
    dy = labels[1:, :] != labels[:-1, :]
    e[:, 1:] |= dx
    e[:, :-1] |= dx
    e[1:, :] |= dy
    e[:-1, :] |= dy
    return e


def texture_edges(image: np.ndarray, instances: np.ndarray) -> np.ndarray:
    """Canny edges of `image` that are not within 1 px of a GT object edge."""
    g = np.asarray(image, dtype=np.float32)
    if g.ndim == 3:
        g = cv2.cvtColor(np.ascontiguousarray(g[..., :3]), cv2.COLOR_RGB2GRAY)
    u8 = np.clip(np.rint(g * 255.0), 0, 255).astype(np.uint8)
    edges = cv2.Canny(u8, CANNY_LOW, CANNY_HIGH) > 0
    obj = cv2.dilate(label_edges(instances).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    return edges & ~obj


def _miss(lab: np.ndarray, min_area: float) -> np.ndarray:
    if min_area <= 0:
        return lab
    ids, counts = np.unique(lab[lab >= 0], return_counts=True)
    small = ids[counts < min_area]
    if len(small):
        lab = np.where(np.isin(lab, small), -1, lab)
    return lab


def _cut_along_texture(seg: np.ndarray, tex: np.ndarray, p: float, rng: np.random.Generator,
                       next_id: int) -> tuple[np.ndarray, int]:
    if p <= 0 or not tex.any():
        return seg, next_id
    out = seg.copy()
    for s in [int(x) for x in np.unique(seg[seg >= 0])]:
        if rng.random() >= p:
            continue
        m = seg == s
        inner = m & ~tex
        comp, n = ndimage.label(inner)
        if n < 2:
            continue
        # edge pixels go to the nearest component (the segmenter's mask boundary sits on the edge)
        _, (iy, ix) = ndimage.distance_transform_edt(comp == 0, return_indices=True)
        near = comp[iy, ix]
        for c in range(2, n + 1):
            out[m & (near == c)] = next_id
            next_id += 1
    return out, next_id


def _split(seg: np.ndarray, p: float, rng: np.random.Generator, next_id: int) -> tuple[np.ndarray, int]:
    if p <= 0:
        return seg, next_id
    H, W = seg.shape
    ys, xs = np.mgrid[0:H, 0:W]
    out = seg.copy()
    for s in [int(x) for x in np.unique(seg[seg >= 0])]:
        if rng.random() >= p:
            continue
        m = seg == s
        if m.sum() < 2:
            continue
        cy, cx = ys[m].mean(), xs[m].mean()
        ang = rng.uniform(0, np.pi)
        side = ((xs - cx) * np.cos(ang) + (ys - cy) * np.sin(ang)) > 0
        if (m & side).any() and (m & ~side).any():
            out[m & side] = next_id
            next_id += 1
    return out, next_id


def _merge(seg: np.ndarray, p: float, rng: np.random.Generator) -> np.ndarray:
    ids = [int(i) for i in np.unique(seg[seg >= 0])]
    if p <= 0 or len(ids) < 2:
        return seg
    parent = {i: i for i in ids}

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    neigh: dict[int, list[int]] = {i: [] for i in ids}
    for a, b in sorted(neighbour_pairs(seg)):
        neigh[a].append(b)
        neigh[b].append(a)
    for i in ids:
        if neigh[i] and rng.random() < p:
            j = neigh[i][int(rng.integers(len(neigh[i])))]
            parent[find(i)] = find(j)
    lut_in = np.array(ids)
    lut_out = np.array([find(i) for i in ids])
    out = seg.copy()
    pos = seg >= 0
    out[pos] = lut_out[np.searchsorted(lut_in, seg[pos])]
    return out


def _leak(seg: np.ndarray, depth: np.ndarray | None, radius: int, rng: np.random.Generator) -> np.ndarray:
    if radius <= 0:
        return seg
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    if depth is not None:
        z = np.where(np.isfinite(depth) & (depth > 0), depth, np.float32(1e6)).astype(np.float32)
        zmax = cv2.dilate(z, k)
        zmin = cv2.erode(z, k)
        jump = (zmax - zmin) > DEPTH_JUMP * np.maximum(zmin, 1e-6)
    else:
        jump = np.ones(seg.shape, bool)
    out = seg.copy()
    ids = [int(i) for i in np.unique(seg[seg >= 0])]
    for s in [ids[int(i)] for i in rng.permutation(len(ids))]:
        if rng.random() >= 0.5:
            continue
        m = seg == s
        grown = (cv2.dilate(m.astype(np.uint8), k) > 0) & ~m & jump
        out[grown] = s
    return out


def segment_view(instances: np.ndarray, knobs: SegmenterKnobs, rng: np.random.Generator,
                 image: np.ndarray | None = None, depth: np.ndarray | None = None) -> np.ndarray:
    """One view's segments (int32, -1 none, ids permuted) from its GT instance map (module doc).

    `image` (H, W, 3 float in [0, 1]) is needed for the texture failure, `depth` (camera z) for
    the leak failure to follow depth discontinuities.
    """
    lab = np.asarray(instances).astype(np.int64)
    H, W = lab.shape
    g = float(np.exp(rng.normal(0.0, GRANULARITY_SIGMA)))   # drawn always: knobs do not shift the stream
    g_miss = float(rng.uniform(0.5, 1.5))
    min_area = MISS_AREA_FRAC * knobs.miss * g_miss * H * W
    lab = _miss(lab, min_area)
    next_id = int(lab.max()) + 1 if (lab >= 0).any() else 0
    if knobs.texture > 0:
        if image is None:
            raise InputError("segmenter: the texture failure needs the view's image")
        tex = texture_edges(image, np.asarray(instances))
        lab, next_id = _cut_along_texture(lab, tex, min(1.0, TEXTURE_P * knobs.texture), rng, next_id)
    lab, next_id = _split(lab, min(1.0, SPLIT_P * knobs.split / g), rng, next_id)
    lab = _merge(lab, min(1.0, MERGE_P * knobs.merge * g), rng)
    radius = int(np.ceil(LEAK_DIAG_FRAC * knobs.leak * np.hypot(H, W))) if knobs.leak > 0 else 0
    lab = _leak(lab, depth, radius, rng)
    lab = _miss(lab, min_area)               # cut parts below the size limit are missed too
    keep = np.unique(lab[lab >= 0])
    out = np.full((H, W), -1, dtype=np.int32)
    if len(keep):
        perm = rng.permutation(len(keep)).astype(np.int32)
        pos = lab >= 0
        out[pos] = perm[np.searchsorted(keep, lab[pos])]
    return out
