"""Labelled surface points of a synthetic scene, from its analytic description (the 3d-points protocol).

Nothing is written to the scene folder (its bytes and fingerprint stay as `gsbench make-scene` wrote
them): the points are drawn at evaluation time. The scene's `gsbench_scene.json` records the generator
parameters (preset, seed, views, resolution); `compose` rebuilds the same primitives, decals and
cameras from them, and the scene's own cameras must match the rebuilt ones (else the scene is refused:
it was edited, or written by another generator version).

Sampling (`surface_points(scene, count, seed)`): `count` rays are split evenly over all views (train
and test; the first `count mod views` views get one more), each through a uniformly random position in
its image (`numpy.random.default_rng(seed)`, drawn view by view in order: u in [0, W), v in [0, H)).
A ray's point is the first surface it hits, found by the generator's own ray caster, and its label is
the class of what it hits there (the object, the floor, the wall, or a decal such as the poster); a
ray that hits nothing gives no point. So every point lies exactly on a surface some view sees.
"""
from __future__ import annotations

import numpy as np

from gsbench.errors import InputError

from .synthetic_render import _intersect, _shade_rays
from .synthetic_spec import SceneSpec, compose

SURFACE_POINTS_IMPL = "synthetic-surface/uniform-pixels-all-views/first-hit/v1"
CAMERA_ATOL = 1e-5   # the scene's cameras and the rebuilt ones agree to this (COLMAP stores them rounded)


def scene_spec(scene) -> SceneSpec:
    """The analytic description of a loaded synthetic scene, rebuilt from its generator parameters and
    checked against the scene's cameras and classes. InputError (one line naming the scene) otherwise."""
    gen = (getattr(scene, "meta", None) or {}).get("synthetic") or {}
    try:
        preset, seed, views = str(gen["preset"]), int(gen["seed"]), int(gen["views"])
        res = (int(gen["resolution"][0]), int(gen["resolution"][1]))
    except (KeyError, TypeError, ValueError, IndexError):
        raise InputError(f"{scene.path}: not a gsbench synthetic scene (no generator parameters in "
                         "gsbench_scene.json): it has no analytic surface to sample") from None
    spec = compose(preset, seed, views, res)
    cams = list(scene.cameras)
    if len(cams) != len(spec.cameras):
        raise InputError(f"{scene.path}: {len(cams)} cameras, but its generator parameters give {len(spec.cameras)}")
    for i, (a, b) in enumerate(zip(cams, spec.cameras)):
        same = (a.width, a.height) == (b.width, b.height) and np.allclose(a.K, b.K, atol=CAMERA_ATOL) and \
            np.allclose(a.world_to_camera, b.world_to_camera, atol=CAMERA_ATOL)
        if not same:
            raise InputError(f"{scene.path}: camera {i} differs from the one its generator parameters give (an "
                             "edited scene, or another generator version): its surface cannot be rebuilt")
    names = list(getattr(scene, "class_names", None) or [])
    if names and names != list(spec.class_names):
        raise InputError(f"{scene.path}: classes {names} differ from its generator's {spec.class_names}")
    return spec


def _view_rays(cam, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Origin (3,) and (n, 3) world directions (camera-space z = 1) through uniform image positions."""
    u = rng.uniform(0.0, cam.width, n)
    v = rng.uniform(0.0, cam.height, n)
    d_cam = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones(n)], axis=1)
    c2w = cam.camera_to_world
    return c2w[:3, 3].copy(), d_cam @ c2w[:3, :3].T


def surface_points(scene, count: int, seed: int) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """((P, 3) float64 points, (P,) int64 class indices into the names, class names) of a synthetic
    scene, P <= count (module docstring: rays that hit nothing give no point)."""
    if int(count) < 1:
        raise ValueError(f"count must be at least 1, got {count!r}")
    spec = scene_spec(scene)
    rng = np.random.default_rng(int(seed))
    n_views = len(spec.cameras)
    base, extra = divmod(int(count), n_views)
    pts, labels = [], []
    for i, cam in enumerate(spec.cameras):
        n = base + (1 if i < extra else 0)
        if n == 0:
            continue
        o, D = _view_rays(cam, n, rng)
        T = np.stack([_intersect(p, o, D) for p in spec.prims])
        _, depth, inst = _shade_rays(spec, o, D, T)     # the generator's own first hit and its instance
        hit = inst >= 0
        pts.append(o + depth[hit, None] * D[hit])
        labels.append(np.array([spec.instance_classes[int(k)] for k in inst[hit]], dtype=np.int64))
    return np.concatenate(pts), np.concatenate(labels), list(spec.class_names)
