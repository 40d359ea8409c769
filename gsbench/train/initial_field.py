"""The initial Gaussians of a run: from the scene's sparse points, uniformly at random in a cube around
the cameras' centroid, or (forward-facing captures with near/far bounds) in the training cameras'
frusta; `scene_init` applies the config's `train.init` to a scene, `init_field` builds the field."""
from __future__ import annotations

from typing import Optional

import numpy as np
import torch

from gsbench.camera import Camera
from gsbench.config import setting
from gsbench.datasets.splits import split_ids
from gsbench.errors import InputError
from gsbench.gaussians import SH_C0, GaussianField
from gsbench.train.densify import inverse_sigmoid


def init_field(points: Optional[np.ndarray], colors: Optional[np.ndarray], mode: str, num_random: int,
               centre: np.ndarray, half_size: float, sh_degree: int, feature_dim: int, seed: int,
               max_points: Optional[int] = None) -> tuple[GaussianField, str]:
    """Initial Gaussians from sparse points (colours if given; a seeded subset of at most `max_points`)
    or uniform in a cube; returns (field, how)."""
    rng = np.random.default_rng(seed)
    if mode == "points":
        if points is None or len(points) == 0:
            raise InputError("train.init.mode=points but the scene has no sparse points")
        xyz = np.asarray(points, dtype=np.float64)
        rgb = (np.asarray(colors, dtype=np.float64) if colors is not None and len(colors) == len(xyz)
               else np.full((len(xyz), 3), 0.5))
        how = f"points ({len(xyz)})"
        if max_points and len(xyz) > int(max_points):
            keep = np.sort(rng.choice(len(xyz), int(max_points), replace=False))
            xyz, rgb = xyz[keep], rgb[keep]
            how = f"points ({len(xyz)} of {len(points)}, seeded subset: train.init.max_points)"
    elif mode == "random":
        n = max(1, int(num_random))
        xyz = centre[None, :] + (rng.random((n, 3)) * 2.0 - 1.0) * half_size
        rgb = rng.random((n, 3))
        how = f"random ({n} in a cube of half-size {half_size:.4g})"
    else:
        raise ValueError(f"train.init.mode must be points or random here, got {mode!r}")
    n = len(xyz)
    # scale = sqrt(mean squared distance to the 3 nearest neighbours) (3DGS)
    from scipy.spatial import cKDTree
    k = min(4, n)
    if k >= 2:
        d, _ = cKDTree(xyz).query(xyz, k=k)
        d2 = np.mean(d[:, 1:] ** 2, axis=1)
        pos = d2[d2 > 0]
        floor = float(np.median(pos)) * 1e-4 if pos.size else 1e-7
        d2 = np.maximum(d2, max(floor, 1e-14))
    else:
        d2 = np.full(n, (half_size * 0.01) ** 2 if half_size > 0 else 1e-4)
    log_s = np.log(np.sqrt(d2))[:, None].repeat(3, 1)
    K = (sh_degree + 1) ** 2
    sh = np.zeros((n, K, 3))
    sh[:, 0, :] = (np.clip(rgb, 0, 1) - 0.5) / SH_C0
    quats = np.zeros((n, 4))
    quats[:, 0] = 1.0
    f32 = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float32)  # noqa: E731
    feats = None
    if feature_dim > 0:
        feats = torch.zeros(n, feature_dim)
    field_ = GaussianField(f32(xyz), f32(log_s), f32(quats), inverse_sigmoid(torch.full((n,), 0.1)), f32(sh), feats)
    return field_, how


FORWARD_FACING_LAYOUTS = ("llff", "3dovs")


def frustum_points(cameras: list[Camera], near: float, far: float, n: int, seed: int) -> np.ndarray:
    """n points uniform over the pixels of the given cameras, at depths uniform in inverse depth
    between `near` and `far` (forward-facing captures: the volume the cameras actually see)."""
    if not (np.isfinite(near) and np.isfinite(far)) or near <= 0 or far <= near:
        raise ValueError(f"frustum init needs 0 < near < far, got near={near}, far={far}")
    rng = np.random.default_rng(seed)
    ci = rng.integers(0, len(cameras), size=n)
    out = np.empty((n, 3))
    inv = 1.0 / near + rng.random(n) * (1.0 / far - 1.0 / near)
    z = 1.0 / inv
    for k, cam in enumerate(cameras):
        sel = np.nonzero(ci == k)[0]
        if sel.size == 0:
            continue
        u = rng.random(sel.size) * cam.width
        v = rng.random(sel.size) * cam.height
        pc = np.stack([(u - cam.cx) / cam.fx * z[sel], (v - cam.cy) / cam.fy * z[sel], z[sel]], axis=1)
        c2w = cam.camera_to_world
        out[sel] = pc @ c2w[:3, :3].T + c2w[:3, 3]
    return out


def init_mode(scene, config: dict) -> str:
    """The concrete init mode: 'auto' = sparse points when the scene has them, else the near/far
    frusta for forward-facing layouts that know their bounds, else a random cube."""
    mode = setting(config, "train.init.mode")
    if mode != "auto":
        return mode
    if scene.has_points:
        return "points"
    meta = getattr(scene, "meta", {}) or {}
    if getattr(scene, "layout", "") in FORWARD_FACING_LAYOUTS and "near" in meta and "far" in meta:
        return "frustum"
    return "random"


def scene_init(scene, config: dict, feature_dim: int):
    """Initial field from the config's init mode (see `init_mode`); returns (field, how)."""
    mode = init_mode(scene, config)
    centres = np.stack([c.center for c in scene.cameras])
    centre = centres.mean(0)
    half = float(scene.extent or 1.0) * float(setting(config, "train.init.random_scale"))
    pc = getattr(scene, "point_colors", None)
    sh = int(setting(config, "train.sh_degree"))
    seed = int(setting(config, "seed"))
    num_random = int(setting(config, "train.init.num_random"))
    if mode == "frustum":
        meta = getattr(scene, "meta", {}) or {}
        if "near" not in meta or "far" not in meta:
            raise ValueError(f"{scene.path}: train.init.mode=frustum needs the scene's near/far bounds "
                             f"(LLFF poses_bounds)")
        near, far = float(meta["near"]), float(meta["far"])
        n = max(1, num_random)
        # the cameras the run trains on (train.views, train.holdout), not the scene's whole training split:
        # a few-view run must not start from points spread over views it never sees
        cams = [scene.cameras[i] for i in split_ids(scene, config)[0]]
        xyz = frustum_points(cams, near, far, n, seed)
        rgb = np.random.default_rng(seed + 1).random((n, 3))
        fld, _ = init_field(xyz, rgb, "points", n, centre, half, sh, feature_dim, seed, None)
        return fld, f"frustum ({n} in the train cameras' frusta, depth {near:.4g}..{far:.4g}, uniform in 1/z)"
    return init_field(scene.points, pc, mode, num_random, centre, half, sh, feature_dim,
                      seed, setting(config, "train.init.max_points"))


__all__ = ["init_field", "scene_init", "init_mode", "frustum_points", "FORWARD_FACING_LAYOUTS"]
