"""The `3d-points` protocol: open-vocabulary segmentation scored in 3D, on labelled surface points.

As OpenGaussian, Dr. Splat and SceneSplat-Bench score it (docs/protocols.md "3D points"):

1. points: POINT_COUNT labelled surface points of a synthetic scene, drawn from its analytic
   description with seed POINT_SEED at evaluation time (gsbench.datasets.surface_points; nothing is
   written to the scene, so its fingerprint and every run id stay as they are);
2. Gaussians: each Gaussian's class is the argmax cosine between its own semantic feature in a query
   mode (`method.gaussian_semantic_features(mode)`, in the space of `method.embed_text(texts, mode)`:
   how the method answers a query) and the text features of the scene's classes; a Gaussian whose
   activated opacity is below OPACITY_FLOOR, or whose feature is zero, gets no class;
3. each point takes the class of its nearest classed Gaussian (centre distance; POINT_MODE);
4. mIoU and mAcc over the classes present among the points: `miou_3d` and `macc_3d` in the configured
   query mode, `miou_3d_<mode>` / `macc_3d_<mode>` per mode scored.

The scoring is gsbench.metrics.points3d. The protocol has no frames. A scene without an analytic
surface (any real capture) is not supported; a method without per-Gaussian semantics (vanilla, or a run
whose semantics were dropped) gets null with the reason.
"""
from __future__ import annotations

import logging
from typing import Optional

import numpy as np

from gsbench.datasets.surface_points import SURFACE_POINTS_IMPL, surface_points
from gsbench.errors import InputError
from gsbench.metrics.points3d import POINTS3D_IMPL, gaussian_classes, point_classes, point_miou_macc

from .block import Block, to_numpy
from .protocol_registry import Protocol, ProtocolContext

log = logging.getLogger(__name__)

POINT_COUNT = 20000      # rays drawn over all views; a ray that hits nothing gives no point
POINT_SEED = 0
OPACITY_FLOOR = 0.1      # Gaussians with activated opacity strictly below this get no class
POINT_MODE = "nearest"
IMPL = (f"{POINTS3D_IMPL[POINT_MODE]}+{SURFACE_POINTS_IMPL}+points-{POINT_COUNT}-seed-{POINT_SEED}"
        f"+opacity-floor-{OPACITY_FLOOR:g}")
BASES = ("miou", "macc")


def gaussian_features(method, mode: str):
    """(features (N, D), None) of a method in query mode `mode`, or (None, the reason)."""
    hook = getattr(method, "gaussian_semantic_features", None)
    if hook is None:
        return None, f"method {method.name} has no per-Gaussian semantic features (gaussian_semantic_features)"
    feats = hook(mode)
    if feats is None:
        return None, f"method {method.name} has no per-Gaussian semantic features in this run"
    return feats, None


def score_mode(method, points: np.ndarray, labels: np.ndarray, names: list[str], mode: str):
    """(PointScores, Gaussian classes) of a method in one query mode, or (None, the reason)."""
    feats, reason = gaussian_features(method, mode)
    if feats is None:
        return None, reason
    text = method.embed_text(list(names), mode)
    fld = method.field
    gcls = gaussian_classes(to_numpy(feats), to_numpy(text), to_numpy(fld.opacity), OPACITY_FLOOR)
    pcls = point_classes(points, to_numpy(fld.means), gcls, POINT_MODE)
    return point_miou_macc(pcls, labels, len(names)), gcls


class Points3DProtocol(Protocol):
    name = "3d-points"
    metric_key = "3d"                 # miou_3d, macc_3d (+ _encode / _decode)
    metrics = BASES
    order = 30
    # opt-in (`gsbench eval RUN --protocol 3d-points`, or with the others: `--protocol 3dovs,lerf,3d-points`):
    # in `auto` it would add metrics that no published cell has, and `verify` compares every metric
    in_auto = False

    def supports(self, scene) -> Optional[str]:
        if not (getattr(scene, "meta", None) or {}).get("synthetic"):
            return "scene has no analytic surface (3d-points needs a gsbench synthetic scene)"
        return None

    def score(self, ctx: ProtocolContext) -> Block:
        out = Block()
        every = [n for b in BASES for m in ctx.modes for n in ctx.names(b, m)]
        reason = self.supports(ctx.scene)
        if reason is None:
            try:
                points, labels, names = surface_points(ctx.scene, POINT_COUNT, POINT_SEED)
            except InputError as e:
                reason = str(e)
        if reason is not None:
            out.skip(every, reason)
            return out
        for mode in ctx.modes:
            sc, extra = score_mode(ctx.method, points, labels, names, mode)
            if sc is None:
                out.skip([n for b in BASES for n in ctx.names(b, mode)], extra)
                continue
            why = "no labelled surface point" if sc.miou is None else None
            for base, value in (("miou", sc.miou), ("macc", sc.macc)):
                for n in ctx.names(base, mode):
                    out.put(n, value, f"{IMPL}+query-{mode}", why)
            out.notes[f"3d-points_{mode}"] = (
                f"{sc.n_points} points, classes present {[names[c] for c in sc.present]}, "
                f"{sc.n_unclassified} unclassified; {int(np.count_nonzero(extra >= 0))} of {len(extra)} "
                f"Gaussians classed (opacity >= {OPACITY_FLOOR:g}, non-zero feature)")
            log.info("3d-points (%s): mIoU %s, mAcc %s over %d points", mode, sc.miou, sc.macc, sc.n_points)
        return out


PROTOCOL = Points3DProtocol()
