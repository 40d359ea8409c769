"""Pseudo-video ordering of the training views (GaussianDS part 1).

Mask propagation (SAM2 or the weight-free propagators) carries masks from frame to frame, so it
works best when neighbouring frames see the scene from nearby poses. `order_views` turns the
unordered training cameras into a chain:

- ``pose``: greedy nearest neighbour on the camera centres, started at an end of the chain (one
  end of the farthest pair of centres), then improved by 2-opt moves on the open path; 2-opt only
  accepts strict improvements, so the total path length is never worse than the greedy one.
- ``random``: a seeded permutation.
- ``filename``: natural sort of the camera names (``frame_2`` before ``frame_10``), ties by index.

The ordering study's metrics (mean adjacent camera-centre distance, adjacent mask IoU) are
implemented in `gsbench.metrics.ordering`; `adjacent_distance` here is a convenience for cameras.
"""
from __future__ import annotations

import re
from typing import Sequence

import numpy as np

from gsbench.camera import Camera
from gsbench.config_keys import ORDERINGS


def camera_centers(cameras: Sequence[Camera], view_ids: Sequence[int]) -> np.ndarray:
    """(N, 3) world-space centres of `cameras[v]` for v in `view_ids`."""
    return np.array([cameras[v].center for v in view_ids], dtype=np.float64).reshape(-1, 3)


def path_length(points: np.ndarray, order: Sequence[int]) -> float:
    """Total length of the open path visiting `points[order]` in sequence."""
    if len(order) < 2:
        return 0.0
    p = points[np.asarray(order)]
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def _greedy_chain(dist: np.ndarray, start: int) -> list[int]:
    n = dist.shape[0]
    visited = np.zeros(n, dtype=bool)
    chain = [start]
    visited[start] = True
    for _ in range(n - 1):
        d = np.where(visited, np.inf, dist[chain[-1]])
        nxt = int(np.argmin(d))  # argmin takes the lowest index on ties: deterministic
        chain.append(nxt)
        visited[nxt] = True
    return chain


def _two_opt(dist: np.ndarray, chain: list[int], max_passes: int = 100) -> list[int]:
    """Open-path 2-opt: reverse chain[i..j] when that shortens the path (ends may move too)."""
    path = np.asarray(chain)
    n = len(path)
    if n < 3:
        return list(path)
    tol = 1e-12 * max(1.0, float(dist.max()))
    for _ in range(max_passes):
        improved = False
        for i in range(n - 1):
            # Reversing path[i..j] replaces edges (i-1, i) and (j, j+1) by (i-1, j) and (i, j+1).
            j = np.arange(i + 1, n)
            a = path[i - 1] if i > 0 else -1
            b = path[i]
            c = path[j]
            d = np.where(j + 1 < n, path[np.minimum(j + 1, n - 1)], -1)
            old = (dist[a, b] if a >= 0 else 0.0) + np.where(d >= 0, dist[c, np.maximum(d, 0)], 0.0)
            new = (dist[a, c] if a >= 0 else 0.0) + np.where(d >= 0, dist[b, np.maximum(d, 0)], 0.0)
            gain = old - new
            k = int(np.argmax(gain))
            if gain[k] > tol:
                jj = int(j[k])
                path[i:jj + 1] = path[i:jj + 1][::-1].copy()
                improved = True
        if not improved:
            break
    return [int(x) for x in path]


def pose_order(centers: np.ndarray) -> list[int]:
    """Indices into `centers` in pose-nearest chain order (greedy from a chain end + 2-opt)."""
    n = len(centers)
    if n <= 2:
        return list(range(n))
    dist = np.linalg.norm(centers[:, None, :] - centers[None, :, :], axis=-1)
    # An end of the chain: one end of the farthest pair of centres (lowest index on ties).
    start = int(np.unravel_index(int(np.argmax(dist)), dist.shape)[0])
    greedy = _greedy_chain(dist, start)
    improved = _two_opt(dist, greedy)
    # 2-opt accepts strict improvements only, so this holds by construction; check it anyway.
    if path_length(centers, improved) > path_length(centers, greedy) + 1e-9:  # pragma: no cover
        return greedy
    return improved


def _natural_key(name: str) -> tuple:
    parts = re.split(r"(\d+)", name)
    return tuple((0, int(p), "") if p.isdigit() else (1, 0, p.lower()) for p in parts if p != "")


def order_views(cameras: Sequence[Camera], view_ids: Sequence[int], mode: str = "pose",
                seed: int = 0) -> list[int]:
    """The pseudo-video order of `view_ids` (a permutation of them) for `mode` in ORDERINGS."""
    view_ids = [int(v) for v in view_ids]
    if len(set(view_ids)) != len(view_ids):
        raise ValueError("order_views: view_ids contain duplicates")
    if mode == "pose":
        idx = pose_order(camera_centers(cameras, view_ids))
        return [view_ids[i] for i in idx]
    if mode == "random":
        perm = np.random.default_rng(seed).permutation(len(view_ids))
        return [view_ids[int(i)] for i in perm]
    if mode == "filename":
        return sorted(view_ids, key=lambda v: (_natural_key(cameras[v].name or ""), v))
    raise ValueError(f"priors.ordering: unknown ordering {mode!r} (expected one of {', '.join(ORDERINGS)})")


def adjacent_distance(cameras: Sequence[Camera], order: Sequence[int]) -> float | None:
    """Mean camera-centre distance between consecutive views of `order` (None for < 2 views)."""
    if len(order) < 2:
        return None
    c = camera_centers(cameras, order)
    return float(np.linalg.norm(np.diff(c, axis=0), axis=1).mean())
