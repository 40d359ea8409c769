"""Weight-free mask propagation along the pseudo-video: the reference partition is carried.

Each view comes with its own segments (int32 map, ids meaningful in that view only, -1 none).
`propagate` walks the pseudo-video order as a video segmenter does: the first frame's segments
become tracks 0..k-1 (the reference partition); for every next frame the previous frame's track
map is warped into it, and the warped (carried) tracks REPLACE the frame's own segments wherever
the warp knows the answer, so the reference frame's cut of the scene (its merges, splits, leaks)
travels along the video and the order of the frames changes the supervision. Where nothing is
carried (disocclusions, failed flow, lost tracks), the frame's segments fill in: a segment that
matches a carried track by IoU (Hungarian, scipy's linear_sum_assignment, at least `min_iou`,
inside the known region) re-seeds that track; an unmatched one of at least `min_track_area`
pixels starts a new track (a new object). A carried track smaller than `min_track_area` pixels
is lost and re-seeded from the segments. `new_objects` says where new tracks may start:

- ``uncarried`` (default): only outside the carried region, so an object the reference frame
  missed or merged stays missed or merged for as long as the warp carries its surroundings;
- ``unmatched``: also a segment of at least `min_track_area` pixels whose IoU with every carried
  track is below `min_iou` (inside the known region) becomes a new track over the carried labels,
  as a video segmenter with periodic re-detection (DEVA-style) adds objects it did not see before.
  A part of a split object overlapping its carried track by at least `min_iou` stays carried.

Two warpers:

- `FlowWarper` (``flow``): DIS optical flow (OpenCV) between consecutive frames, each pixel of the
  new frame looks up its source through the backward flow; a forward-backward consistency check
  (|B(p) + F(p + B(p))|^2 < 0.01 (|B|^2 + |F|^2) + 0.5 px^2, Sundaram et al. 2010) marks
  occluded / unreliable pixels unknown.
- `ReprojectWarper` (``reproject``): unproject the previous frame with metric depth and forward
  splat into the new frame with a z-buffer; pixels that receive no point are unknown.

IoU for matching is computed inside the known region of the warp only (pixels the warp could
say something about), so an object that leaves the view does not lose its track for that alone.
The adjacent-frame metrics that score the result are in `gsbench.metrics.ordering`.
"""
from __future__ import annotations

from typing import Callable, Mapping, Sequence

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment
from tqdm.auto import tqdm

from gsbench.camera import Camera
from gsbench.config_keys import NEW_OBJECT_RULES
from gsbench.priors import warp as W

DEFAULT_MIN_IOU = 0.3
MIN_TRACK_AREA_FRAC = 0.001
FB_ALPHA = 0.01
FB_BETA = 0.5
MIN_FLOW_SIDE = 16

# warp(prev_view, cur_view, prev_labels) -> (labels in cur frame (-1 none), known bool map)
Warper = Callable[[int, int, np.ndarray], tuple[np.ndarray, np.ndarray]]


def _gray_u8(img: np.ndarray) -> np.ndarray:
    a = np.asarray(img, dtype=np.float32)
    if a.ndim == 3:
        a = cv2.cvtColor(np.ascontiguousarray(a[..., :3]), cv2.COLOR_RGB2GRAY)
    return np.clip(np.rint(a * 255.0), 0, 255).astype(np.uint8)


class FlowWarper:
    """Backward warping with DIS optical flow and a forward-backward check."""

    id = "flow-dis-fb"

    def __init__(self, images: Mapping[int, np.ndarray], preset: int = cv2.DISOPTICAL_FLOW_PRESET_MEDIUM):
        self.gray = {int(v): _gray_u8(im) for v, im in images.items()}
        self.dis = cv2.DISOpticalFlow_create(preset)

    def flows(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """(F: a -> b, B: b -> a) as H x W x 2 float32 pixel displacements."""
        ga, gb = self.gray[a], self.gray[b]
        H, Wd = ga.shape
        # OpenCV's DIS needs a side of at least 12 px: tiny frames are padded (reflected) and cropped
        ph, pw = max(0, MIN_FLOW_SIDE - H), max(0, MIN_FLOW_SIDE - Wd)
        if ph or pw:
            ga = cv2.copyMakeBorder(ga, 0, ph, 0, pw, cv2.BORDER_REFLECT)
            gb = cv2.copyMakeBorder(gb, 0, ph, 0, pw, cv2.BORDER_REFLECT)
        F = self.dis.calc(ga, gb, None)[:H, :Wd]
        B = self.dis.calc(gb, ga, None)[:H, :Wd]
        return np.ascontiguousarray(F), np.ascontiguousarray(B)

    def __call__(self, prev: int, cur: int, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        F, B = self.flows(prev, cur)
        H, Wd = labels.shape
        xs, ys = np.meshgrid(np.arange(Wd, dtype=np.float32), np.arange(H, dtype=np.float32))
        qx = xs + B[..., 0]
        qy = ys + B[..., 1]
        Fq = cv2.remap(F, qx, qy, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        err = ((B + Fq) ** 2).sum(-1)
        mag = (B ** 2).sum(-1) + (Fq ** 2).sum(-1)
        ix = np.rint(qx).astype(np.int64)
        iy = np.rint(qy).astype(np.int64)
        inside = (ix >= 0) & (ix < Wd) & (iy >= 0) & (iy < H)
        known = inside & (err < FB_ALPHA * mag + FB_BETA)
        out = np.full((H, Wd), -1, dtype=np.int32)
        out[known] = labels[iy[known], ix[known]]
        return out, known


class ReprojectWarper:
    """Forward z-buffer reprojection with metric (camera-space z) depth maps at the mask size."""

    id = "reproject-zbuffer"

    def __init__(self, cameras: Mapping[int, Camera], depths: Mapping[int, np.ndarray],
                 valids: Mapping[int, np.ndarray]):
        self.cameras, self.depths, self.valids = cameras, depths, valids

    def __call__(self, prev: int, cur: int, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        src, dst = self.cameras[prev], self.cameras[cur]
        pts, flat = W.unproject(self.depths[prev], self.valids[prev], src)
        vals = labels.reshape(-1)[flat].astype(np.int32)
        out, zmap = W.zbuffer_splat(pts, vals, dst, fill=np.int32(-1))
        return out, np.isfinite(zmap)


def iou_matrix(a: np.ndarray, b: np.ndarray, known: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IoU of every label of `a` against every label of `b` (labels >= 0), inside `known`.

    Returns (ids_a, ids_b, iou[len(ids_a), len(ids_b)]).
    """
    if known is None:
        known = np.ones(a.shape, dtype=bool)
    av = a[known].astype(np.int64)
    bv = b[known].astype(np.int64)
    ids_a = np.unique(av[av >= 0])
    ids_b = np.unique(bv[bv >= 0])
    if len(ids_a) == 0 or len(ids_b) == 0:
        return ids_a, ids_b, np.zeros((len(ids_a), len(ids_b)))
    ia = np.searchsorted(ids_a, av)
    ib = np.searchsorted(ids_b, bv)
    ia = np.where(av >= 0, ia, len(ids_a))        # extra bin = unlabelled
    ib = np.where(bv >= 0, ib, len(ids_b))
    joint = np.bincount(ia * (len(ids_b) + 1) + ib, minlength=(len(ids_a) + 1) * (len(ids_b) + 1))
    joint = joint.reshape(len(ids_a) + 1, len(ids_b) + 1)
    inter = joint[:-1, :-1].astype(np.float64)
    area_a = joint[:-1, :].sum(1).astype(np.float64)
    area_b = joint[:, :-1].sum(0).astype(np.float64)
    union = area_a[:, None] + area_b[None, :] - inter
    iou = np.divide(inter, union, out=np.zeros_like(inter), where=union > 0)
    return ids_a, ids_b, iou


def match_segments(warped: np.ndarray, known: np.ndarray, segments: np.ndarray,
                   min_iou: float = DEFAULT_MIN_IOU) -> dict[int, int]:
    """Hungarian matching of segment ids to warped track ids; returns {segment id: track id}."""
    return _match(*iou_matrix(warped, segments, known), min_iou)


def _match(tracks: np.ndarray, segs: np.ndarray, iou: np.ndarray, min_iou: float) -> dict[int, int]:
    if iou.size == 0:
        return {}
    rows, cols = linear_sum_assignment(-iou)
    return {int(segs[c]): int(tracks[r]) for r, c in zip(rows, cols) if iou[r, c] >= min_iou}


def _unmatched_segments(segs: np.ndarray, iou: np.ndarray, min_iou: float) -> set[int]:
    """Segment ids (seen inside the known region) whose IoU with every carried track is below min_iou."""
    if len(segs) == 0:
        return set()
    best = iou.max(axis=0) if iou.shape[0] else np.zeros(len(segs))
    return {int(s) for s, b in zip(segs, best) if b < min_iou}


def propagate(order: Sequence[int], segments: Mapping[int, np.ndarray], warper: Warper,
              min_iou: float = DEFAULT_MIN_IOU, min_track_area: int | None = None,
              new_objects: str = "uncarried", progress: bool = False) -> dict[int, np.ndarray]:
    """Per-view track maps (int32, -1 none): the reference partition carried along `order`."""
    if new_objects not in NEW_OBJECT_RULES:
        raise ValueError(f"new_objects must be one of {NEW_OBJECT_RULES}, got {new_objects!r}")
    tracks: dict[int, np.ndarray] = {}
    next_id = 0
    prev = None
    for v in tqdm(order, desc="propagate masks", disable=not progress, leave=False):
        seg = np.asarray(segments[v]).astype(np.int32, copy=False)
        area = int(min_track_area) if min_track_area is not None else max(1, int(MIN_TRACK_AREA_FRAC * seg.size))
        out = np.full(seg.shape, -1, dtype=np.int32)
        carried = np.zeros(seg.shape, dtype=bool)
        mapping: dict[int, int] = {}
        if prev is not None:
            warped, known = warper(prev, v, tracks[prev])
            carried = known & (warped >= 0)
            ids, counts = np.unique(warped[carried], return_counts=True)
            lost = ids[counts < area]
            if len(lost):
                carried &= ~np.isin(warped, lost)
            out[carried] = warped[carried]
            tids, sids, iou = iou_matrix(np.where(carried, warped, -1), seg, known)
            mapping = _match(tids, sids, iou, min_iou)
            if new_objects == "unmatched":
                for s in sorted(_unmatched_segments(sids, iou, min_iou) - set(mapping)):
                    px = seg == s
                    if int(px.sum()) >= area:
                        out[px] = next_id
                        next_id += 1
                        carried |= px         # settled: the fill below leaves it alone
        fill = ~carried & (seg >= 0)
        for s in np.unique(seg[fill]):
            px = fill & (seg == s)
            if int(s) in mapping:
                out[px] = mapping[int(s)]
            elif prev is None or int(px.sum()) >= area:
                out[px] = next_id
                next_id += 1
        tracks[v] = out
        prev = v
    return tracks
