"""A tiny ray-cast test scene for the priors tests (no dependency on the scene generator).

Textured spheres on a textured floor disk, seen by cameras on two rings around the origin
(world up = +z). Everything (depth, instances, classes) is exact ray-casting, so the tests can
check the priors against ground truth. Camera names follow capture order: ring 1 anticlockwise,
then ring 2 anticlockwise again, so filename order has one long jump that pose order avoids.
"""
from __future__ import annotations

import numpy as np

from gsbench.camera import Camera
from gsbench.datasets.base import Scene

SPHERES = [  # centre, radius, class index
    ((0.0, 0.0, 0.35), 0.35, 0),
    ((0.8, 0.3, 0.25), 0.25, 1),
    ((-0.6, 0.7, 0.3), 0.3, 2),
    ((-0.4, -0.8, 0.2), 0.2, 1),
]
CLASS_NAMES = ["mug", "ball", "apple", "table"]
FLOOR_RADIUS = 2.0
COLORS = np.array([[0.9, 0.3, 0.2], [0.2, 0.6, 0.9], [0.3, 0.8, 0.3], [0.7, 0.6, 0.4]])


def look_at(center, target=(0.0, 0.0, 0.2), up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """World-to-camera (OpenCV: x right, y down, z forward) for a camera at `center` looking at `target`."""
    c = np.asarray(center, float)
    f = np.asarray(target, float) - c
    f /= np.linalg.norm(f)
    r = np.cross(f, np.asarray(up, float))
    r /= np.linalg.norm(r)
    d = np.cross(f, r)
    R = np.stack([r, d, f])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = -R @ c
    return T


def ring_cameras(n_per_ring=8, width=96, height=72, arc_deg=300.0, radius=3.0, heights=(1.2, 2.0)):
    cams = []
    fx = 0.9 * width
    K = np.array([[fx, 0, width / 2], [0, fx, height / 2], [0, 0, 1.0]])
    k = 0
    for h in heights:
        for a in np.linspace(0.0, np.radians(arc_deg), n_per_ring):
            c = (radius * np.cos(a), radius * np.sin(a), h)
            cams.append(Camera(K, look_at(c), width, height, name=f"frame_{k:03d}.png"))
            k += 1
    return cams


def _texture(p: np.ndarray) -> np.ndarray:
    return (0.55 + 0.15 * np.sin(11 * p[..., 0]) * np.sin(13 * p[..., 1] + 1.0)
            + 0.15 * np.sin(17 * p[..., 2] + 7 * p[..., 0]) + 0.1 * np.sin(23 * p[..., 1] - 5 * p[..., 2]))


def raycast(cam: Camera):
    """(rgb HxWx3, z HxW with inf where nothing is hit, instance HxW int32 -1 none)."""
    H, W = cam.height, cam.width
    ys, xs = np.mgrid[0:H, 0:W]
    pix = np.stack([xs + 0.5, ys + 0.5, np.ones_like(xs, dtype=float)], -1).reshape(-1, 3)
    dc = pix @ np.linalg.inv(cam.K).T              # camera-space direction with z = 1
    R = cam.world_to_camera[:3, :3]
    o = cam.center
    dw = dc @ R                                    # world direction (R^T d)
    best = np.full(len(dw), np.inf)
    inst = np.full(len(dw), -1, np.int32)
    for k, (c, r, _) in enumerate(SPHERES):
        oc = o - np.asarray(c)
        a = (dw * dw).sum(1)
        b = 2 * (dw @ oc)
        cc = oc @ oc - r * r
        disc = b * b - 4 * a * cc
        ok = disc >= 0
        t = np.where(ok, (-b - np.sqrt(np.where(ok, disc, 0))) / (2 * a), np.inf)
        t = np.where(t > 1e-6, t, np.inf)
        hit = t < best
        best[hit] = t[hit]
        inst[hit] = k
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -o[2] / dw[:, 2]
    p = o + dw * np.where(np.isfinite(t), t, 0)[:, None]
    ok = np.isfinite(t) & (t > 1e-6) & (np.hypot(p[:, 0], p[:, 1]) < FLOOR_RADIUS) & (t < best)
    best[ok] = t[ok]
    inst[ok] = len(SPHERES)
    pw = o + dw * np.where(np.isfinite(best), best, 0)[:, None]
    cls = np.array([s[2] for s in SPHERES] + [3])
    rgb = np.zeros((len(dw), 3))
    hitany = inst >= 0
    rgb[hitany] = COLORS[cls[inst[hitany]]] * _texture(pw[hitany])[:, None]
    return (np.clip(rgb, 0, 1).reshape(H, W, 3).astype(np.float32), best.reshape(H, W),
            inst.reshape(H, W))


def make_sphere_scene(n_per_ring=8, width=96, height=72, **kw) -> Scene:
    cams = ring_cameras(n_per_ring, width, height, **kw)
    cache = {}

    def get(i):
        if i not in cache:
            cache[i] = raycast(cams[i])
        return cache[i]

    def depth(i):
        z = get(i)[1].astype(np.float32)
        return np.where(np.isfinite(z), z, 0.0).astype(np.float32)

    def classes(i):
        inst = get(i)[2]
        lut = np.array([s[2] for s in SPHERES] + [3, -1])
        return lut[np.where(inst >= 0, inst, len(lut) - 1)].astype(np.int32)

    rng = np.random.default_rng(0)
    pts = []
    for c, r, _ in SPHERES:
        d = rng.standard_normal((300, 3))
        pts.append(np.asarray(c) + r * d / np.linalg.norm(d, axis=1, keepdims=True))
    a = rng.uniform(0, 2 * np.pi, 600)
    rr = FLOOR_RADIUS * np.sqrt(rng.uniform(0, 1, 600))
    pts.append(np.stack([rr * np.cos(a), rr * np.sin(a), np.zeros(600)], 1))
    n = len(cams)
    return Scene(name="spheres", path="<memory:spheres>", layout="memory", cameras=cams,
                 train_ids=list(range(n)), test_ids=[], image_paths=[], class_names=list(CLASS_NAMES),
                 points=np.concatenate(pts), extent=3.0, depth_loader=depth, classes_loader=classes,
                 instances_loader=lambda i: get(i)[2].copy(),
                 instance_classes={k: s[2] for k, s in enumerate(SPHERES)} | {len(SPHERES): 3},
                 queries=list(CLASS_NAMES), image_loader=lambda i: get(i)[0].copy())

