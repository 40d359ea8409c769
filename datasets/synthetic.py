"""Synthetic indoor scenes from an analytic ray caster (numpy): an independent ground truth.

A scene is a textured floor (z = 0) and back wall (y = WALL_Y), 3 to 8 objects of distinct classes
(spheres, boxes turned about z, upright cylinders) with procedural textures, and texture-only
regions (a poster on the wall; a rug on the floor in larger presets): class boundaries with no depth
edge. Shading is Lambertian under fixed lights with no shadows, so colour does not depend on the
viewpoint and removing an object changes only the pixels it covered.

Per view the generator writes RGB, GT depth (camera-space z), instance and class maps and, per
object, the view rendered without it. Pixel (col j, row i) is the ray through (j + 0.5, i + 0.5),
the convention of `Camera.project`. Rays are built with camera-space z = 1, so the ray parameter of
a hit is its depth.

Output folder (layout "both"; "3dovs" and "lerf" write the subsets they need):
  images/frame_00001.png ...            RGB (1-based names: label frame_00041 is index 40)
  sparse/0/*.bin                        COLMAP model (PINHOLE cameras, surface sample points)
  poses_bounds.npy                      LLFF poses (3dovs)
  segmentations/classes.txt, segmentations/<idx>/<class>.png  (3dovs; every class of every view)
  label/<preset>/frame_00001.json ...   LERF-OVS polygons of objects and decals (lerf)
  gt/depth/<stem>.npy                   float32 camera-space z, 0 where no surface
  gt/instances/<stem>.png               uint16, instance id + 1, 0 = none
  gt/removal/<stem>/<id>.png            RGB without object <id>
  gsbench_scene.json                    classes, instances, split, queries, generator parameters
"""
from __future__ import annotations

import math
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from gsbench.errors import InputError
from gsbench.scene import Camera
from gsbench.store import write_json_atomic

from .colmap import write_colmap
from .imageio import write_npy, write_png
from .llff import write_poses_bounds
from .ovs import mask_to_polygons

WALL_Y = 1.0
FAR = 50.0
LAYOUT_CHOICES = ("both", "3dovs", "lerf")
GENERATOR_VERSION = 1

PRESETS: dict[str, dict] = {
    # tests and the demo: small enough for CPU training in minutes
    "tabletop-small": dict(objects=(4, 5), views=24, resolution=(128, 96), decals=("poster",), path="arc",
                           arc_deg=110.0, elevation_deg=(24.0, 38.0), radius=(1.75, 2.0), hfov_deg=55.0, points=4000, area=(0.55, 0.4)),
    # benchmarks: more objects, a second decal, hemisphere cameras
    "room-medium": dict(objects=(7, 8), views=60, resolution=(320, 240), decals=("poster", "rug"), path="hemisphere",
                        arc_deg=150.0, elevation_deg=(18.0, 55.0), radius=(2.1, 2.6), hfov_deg=60.0, points=20000, area=(0.8, 0.55)),
}

# class name, shape, colour 1, colour 2, pattern
OBJECT_POOL = [
    ("ball", "sphere", (0.85, 0.15, 0.12), (0.95, 0.88, 0.25), "stripes"),
    ("orange", "sphere", (0.96, 0.55, 0.08), (0.86, 0.42, 0.04), "dots"),
    ("globe", "sphere", (0.18, 0.38, 0.85), (0.30, 0.72, 0.30), "checker"),
    ("book", "box", (0.12, 0.28, 0.62), (0.92, 0.86, 0.72), "stripes"),
    ("box", "box", (0.70, 0.54, 0.32), (0.52, 0.38, 0.22), "checker"),
    ("brick", "box", (0.68, 0.22, 0.16), (0.80, 0.74, 0.68), "checker"),
    ("mug", "cylinder", (0.92, 0.92, 0.88), (0.20, 0.48, 0.82), "stripes"),
    ("can", "cylinder", (0.80, 0.08, 0.10), (0.86, 0.86, 0.86), "stripes"),
    ("vase", "cylinder", (0.28, 0.62, 0.52), (0.90, 0.78, 0.36), "dots"),
    ("candle", "cylinder", (0.96, 0.92, 0.78), (0.70, 0.30, 0.55), "checker"),
]
LIGHTS = [(np.array([-0.4, -0.6, 0.8]) / np.linalg.norm([-0.4, -0.6, 0.8]), 0.55),
          (np.array([0.6, -0.3, 0.5]) / np.linalg.norm([0.6, -0.3, 0.5]), 0.25)]
AMBIENT = 0.3


@dataclass
class Prim:
    """One surface: kind in floor | wall | sphere | box | cylinder, with its class and instance."""

    kind: str
    name: str
    instance: int
    center: np.ndarray = field(default_factory=lambda: np.zeros(3))
    size: np.ndarray = field(default_factory=lambda: np.zeros(3))  # sphere (r,), box half extents, cylinder (r, h)
    yaw: float = 0.0
    colors: tuple = ((0.5, 0.5, 0.5), (0.5, 0.5, 0.5))
    pattern: str = "plain"
    period: float = 0.1


@dataclass
class Decal:
    """A texture-only region: a rectangle on the wall (x, z) or the floor (x, y)."""

    name: str
    instance: int
    surface: str
    lo: np.ndarray
    hi: np.ndarray
    colors: tuple


@dataclass
class SceneSpec:
    prims: list[Prim]
    decals: list[Decal]
    cameras: list[Camera]
    class_names: list[str]
    instance_classes: dict[int, int]
    instance_names: dict[int, str]
    removable: list[int]


# ------------------------------------------------------------------------------------ composition
def _look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """OpenCV world-to-camera looking from eye to target with world +z up."""
    f = target - eye
    f = f / np.linalg.norm(f)
    r = np.cross(f, [0.0, 0.0, 1.0])
    r = r / max(np.linalg.norm(r), 1e-12)
    d = np.cross(f, r)
    R = np.stack([r, d, f], axis=1)  # camera-to-world rotation
    w2c = np.eye(4)
    w2c[:3, :3] = R.T
    w2c[:3, 3] = -R.T @ eye
    return w2c


def compose(preset: str, seed: int = 0, views: int | None = None, resolution: tuple[int, int] | None = None) -> SceneSpec:
    """Seeded scene layout and cameras for a preset (no rendering)."""
    if preset not in PRESETS:
        raise InputError(f"unknown preset {preset!r}; choose one of {', '.join(PRESETS)}")
    cfg = PRESETS[preset]
    n_views = int(views if views is not None else cfg["views"])
    if not 2 <= n_views <= 1000:
        raise InputError(f"--views must be between 2 and 1000, got {n_views}")
    W, H = resolution if resolution is not None else cfg["resolution"]
    if not (8 <= W <= 8192 and 8 <= H <= 8192):
        raise InputError(f"--resolution must be between 8x8 and 8192x8192, got {W}x{H}")
    rng = np.random.default_rng(seed)
    lo, hi = cfg["objects"]
    n_obj = int(rng.integers(lo, hi + 1))
    n_obj = max(3, min(8, n_obj))
    # distinct classes, at least one of each shape
    by_shape = {s: [k for k, o in enumerate(OBJECT_POOL) if o[1] == s] for s in ("sphere", "box", "cylinder")}
    chosen = [int(rng.choice(v)) for v in by_shape.values()]
    rest = [k for k in range(len(OBJECT_POOL)) if k not in chosen]
    chosen += [int(k) for k in rng.choice(rest, size=n_obj - 3, replace=False)]
    prims: list[Prim] = []
    placed: list[tuple[float, float, float]] = []
    ax, ay = cfg["area"]
    for inst, k in enumerate(chosen):
        name, shape, c1, c2, pattern = OBJECT_POOL[k]
        if shape == "sphere":
            size = np.array([rng.uniform(0.10, 0.17), 0, 0])
            foot = size[0]
        elif shape == "box":
            flat = name == "book"
            size = np.array([rng.uniform(0.10, 0.18), rng.uniform(0.07, 0.13),
                             rng.uniform(0.025, 0.045) if flat else rng.uniform(0.07, 0.15)])
            foot = float(np.hypot(size[0], size[1]))
        else:
            size = np.array([rng.uniform(0.06, 0.11), rng.uniform(0.14, 0.32), 0])
            foot = size[0]
        for _ in range(500):
            x, y = rng.uniform(-ax, ax), rng.uniform(-ay, ay) + 0.05
            if all(math.hypot(x - px, y - py) > foot + pr + 0.05 for px, py, pr in placed):
                break
        else:
            raise RuntimeError("could not place the objects without overlap; try another seed")
        placed.append((x, y, foot))
        z = size[0] if shape == "sphere" else (size[2] if shape == "box" else 0.0)
        prims.append(Prim(shape, name, inst, np.array([x, y, z]), size, float(rng.uniform(0, np.pi)),
                          (c1, c2), pattern, float(rng.uniform(0.04, 0.08))))
    n = len(prims)
    prims.append(Prim("floor", "floor", n, colors=((0.74, 0.64, 0.50), (0.60, 0.50, 0.38)), pattern="checker", period=0.3))
    prims.append(Prim("wall", "wall", n + 1, colors=((0.86, 0.83, 0.76), (0.76, 0.79, 0.82)), pattern="wallstripes",
                      period=0.3))
    decals: list[Decal] = []
    inst = n + 2
    for d in cfg["decals"]:
        if d == "poster":
            x0, z0 = rng.uniform(-0.6, 0.1), rng.uniform(0.35, 0.45)
            decals.append(Decal("poster", inst, "wall", np.array([x0, z0]), np.array([x0 + rng.uniform(0.45, 0.6),
                                z0 + rng.uniform(0.32, 0.42)]), ((0.10, 0.55, 0.75), (0.95, 0.35, 0.45))))
        elif d == "rug":
            x0, y0 = rng.uniform(-0.9, -0.2), rng.uniform(-0.9, -0.6)
            decals.append(Decal("rug", inst, "floor", np.array([x0, y0]), np.array([x0 + rng.uniform(0.6, 0.9),
                                y0 + rng.uniform(0.4, 0.6)]), ((0.55, 0.12, 0.18), (0.20, 0.25, 0.55))))
        inst += 1
    cameras = _cameras(cfg, n_views, W, H, rng)
    names = sorted({p.name for p in prims} | {d.name for d in decals})
    inst_cls = {p.instance: names.index(p.name) for p in prims}
    inst_cls.update({d.instance: names.index(d.name) for d in decals})
    inst_names = {p.instance: p.name for p in prims}
    inst_names.update({d.instance: d.name for d in decals})
    return SceneSpec(prims, decals, cameras, names, inst_cls, inst_names, list(range(n)))


def _cameras(cfg: dict, n: int, W: int, H: int, rng: np.random.Generator) -> list[Camera]:
    f = 0.5 * W / math.tan(math.radians(cfg["hfov_deg"]) / 2)
    K = np.array([[f, 0, W / 2.0], [0, f, H / 2.0], [0, 0, 1.0]])
    half = math.radians(cfg["arc_deg"]) / 2
    e0, e1 = (math.radians(e) for e in cfg["elevation_deg"])
    cams = []
    for i in range(n):
        if cfg["path"] == "arc":
            az = -half + 2 * half * i / max(n - 1, 1) + rng.normal(0, 0.02)
            el = rng.uniform(e0, e1)
        else:  # hemisphere: stratified azimuth, elevation spread by a golden-ratio sequence
            az = -half + 2 * half * (i + rng.uniform(0.2, 0.8)) / n
            el = e0 + (e1 - e0) * ((i * 0.618034) % 1.0)
        r = rng.uniform(*cfg["radius"])
        target = np.array([0.0, 0.05, 0.18]) + rng.normal(0, 0.04, 3)
        eye = target + r * np.array([math.sin(az) * math.cos(el), -math.cos(az) * math.cos(el), math.sin(el)])
        eye[1] = min(eye[1], WALL_Y - 0.4)
        cams.append(Camera(K, _look_at(eye, target), W, H, name=f"frame_{i + 1:05d}.png"))
    return cams


# ------------------------------------------------------------------------------------ ray casting
def camera_rays(cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Origin (3,) and world directions (H*W, 3) with camera-space z = 1 (ray parameter = depth)."""
    jj, ii = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    d_cam = np.stack([(jj - cam.cx) / cam.fx, (ii - cam.cy) / cam.fy, np.ones_like(jj)], -1).reshape(-1, 3)
    c2w = cam.camera_to_world
    return c2w[:3, 3].copy(), _matvec(d_cam, c2w[:3, :3])


def _matvec(X: np.ndarray, M: np.ndarray) -> np.ndarray:
    """Rows of X mapped by M (X @ M.T), written out: far faster than a BLAS call on tall N x 3 arrays."""
    return np.stack([X[:, 0] * M[r, 0] + X[:, 1] * M[r, 1] + X[:, 2] * M[r, 2] for r in range(3)], axis=1)


def _rot_z(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _safe_div(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(np.abs(b) > 1e-12, a / np.where(np.abs(b) > 1e-12, b, 1.0), np.inf)
    return out


def _intersect(p: Prim, o: np.ndarray, D: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """Ray parameter of the first hit in front of the origin (inf for a miss)."""
    inf = np.full(len(D), np.inf)
    if p.kind == "floor":
        t = _safe_div(np.full(len(D), -o[2]), D[:, 2])
    elif p.kind == "wall":
        t = _safe_div(np.full(len(D), WALL_Y - o[1]), D[:, 1])
    elif p.kind == "sphere":
        oc = o - p.center
        a = np.einsum("ij,ij->i", D, D)
        b = 2 * D @ oc
        c = oc @ oc - p.size[0] ** 2
        disc = b * b - 4 * a * c
        sq = np.sqrt(np.maximum(disc, 0))
        t0 = (-b - sq) / (2 * a)
        t1 = (-b + sq) / (2 * a)
        t = np.where(t0 > eps, t0, t1)
        t = np.where(disc >= 0, t, np.inf)
    elif p.kind == "box":
        R = _rot_z(p.yaw)
        ol = R.T @ (o - p.center)
        Dl = _matvec(D, R.T)  # rows: R^T d
        lo, hi = -p.size, p.size
        t1 = _safe_div(lo[None] - ol[None], Dl)
        t2 = _safe_div(hi[None] - ol[None], Dl)
        # a ray parallel to a slab is inside it (both inf with one sign flipped) or outside (miss)
        par = np.abs(Dl) <= 1e-12
        inside = (ol[None] >= lo[None]) & (ol[None] <= hi[None])
        tmin_ax = np.where(par, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
        tmax_ax = np.where(par, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
        tn, tf = tmin_ax.max(1), tmax_ax.min(1)
        t = np.where((tf >= tn) & (tn > eps), tn, np.inf)
    elif p.kind == "cylinder":
        r, h = p.size[0], p.size[1]
        ox, oy = o[0] - p.center[0], o[1] - p.center[1]
        a = D[:, 0] ** 2 + D[:, 1] ** 2
        b = 2 * (ox * D[:, 0] + oy * D[:, 1])
        c = ox * ox + oy * oy - r * r
        disc = b * b - 4 * a * c
        with np.errstate(divide="ignore", invalid="ignore"):
            ts = np.where((disc >= 0) & (a > 1e-12), (-b - np.sqrt(np.maximum(disc, 0))) / (2 * np.maximum(a, 1e-12)), np.inf)
        zs = o[2] + ts * D[:, 2]
        ts = np.where((ts > eps) & (zs >= 0) & (zs <= h), ts, np.inf)
        tc = _safe_div(np.full(len(D), h - o[2]), D[:, 2])
        xc, yc = ox + tc * D[:, 0], oy + tc * D[:, 1]
        with np.errstate(invalid="ignore"):
            tc = np.where((tc > eps) & (xc * xc + yc * yc <= r * r), tc, np.inf)
        t = np.minimum(ts, tc)
    else:
        return inf
    t = np.where(np.isfinite(t) & (t > eps) & (t < FAR), t, np.inf)
    return t


def _pattern(kind: str, u: np.ndarray, v: np.ndarray, period: float) -> np.ndarray:
    """Weight of colour 2 in [0, 1] for surface coordinates (u, v) in metres."""
    if kind == "checker":
        return ((np.floor(u / period) + np.floor(v / period)) % 2).astype(np.float64)
    if kind == "stripes":
        return (np.sin(2 * np.pi * v / period) > 0.3).astype(np.float64)
    if kind == "dots":
        cu = u / period - np.floor(u / period) - 0.5
        cv = v / period - np.floor(v / period) - 0.5
        return (cu * cu + cv * cv < 0.09).astype(np.float64)
    if kind == "wallstripes":
        return 0.5 + 0.5 * np.sin(2 * np.pi * u / period)
    return np.zeros_like(u)


def _shade(p: Prim, X: np.ndarray) -> np.ndarray:
    """RGB of primitive p at world hit points X (K x 3)."""
    if p.kind == "floor":
        n = np.tile([0.0, 0.0, 1.0], (len(X), 1))
        u, v = X[:, 0] + 10, X[:, 1] + 10
        w = _pattern(p.pattern, u, v, p.period) * 0.8 + 0.2 * (np.sin(40 * X[:, 0] + 3 * np.sin(7 * X[:, 1])) > 0.6)
    elif p.kind == "wall":
        n = np.tile([0.0, -1.0, 0.0], (len(X), 1))
        w = _pattern(p.pattern, X[:, 0] + 10, X[:, 2], p.period)
    elif p.kind == "sphere":
        q = X - p.center
        r = p.size[0]
        n = q / r
        az = np.arctan2(q[:, 1], q[:, 0]) + p.yaw
        u = az * r
        v = np.arccos(np.clip(q[:, 2] / r, -1, 1)) * r
        w = _pattern(p.pattern, u + 10, v, p.period)
    elif p.kind == "box":
        R = _rot_z(p.yaw)
        ql = _matvec(X - p.center, R.T)
        rel = np.abs(ql) / p.size
        ax = np.argmax(rel, axis=1)
        nl = np.zeros_like(ql)
        nl[np.arange(len(ql)), ax] = np.sign(ql[np.arange(len(ql)), ax])
        n = _matvec(nl, R)
        # face coordinates: the two other local axes
        a1 = np.where(ax == 0, ql[:, 1], ql[:, 0])
        a2 = np.where(ax == 2, ql[:, 1], ql[:, 2])
        w = _pattern(p.pattern, a1 + 10, a2 + 10, p.period)
    else:  # cylinder
        r, h = p.size[0], p.size[1]
        q = X - p.center
        cap = np.abs(q[:, 2] - h) < 1e-7 * max(1.0, h)
        radial = q.copy()
        radial[:, 2] = 0
        n = np.where(cap[:, None], np.array([0.0, 0.0, 1.0]), radial / r)
        ang = np.arctan2(q[:, 1], q[:, 0]) + p.yaw
        u = np.where(cap, q[:, 0], ang * r)
        v = np.where(cap, q[:, 1], q[:, 2])
        w = _pattern(p.pattern, u + 10, v + 10, p.period)
    c1, c2 = np.array(p.colors[0]), np.array(p.colors[1])
    albedo = c1 * (1 - w[:, None]) + c2 * w[:, None]
    return albedo * _light(n)[:, None]


def _light(n: np.ndarray) -> np.ndarray:
    s = np.full(len(n), AMBIENT)
    for L, k in LIGHTS:
        s = s + k * np.maximum(0.0, n @ L)
    return s


def _decal_mask(d: Decal, X: np.ndarray) -> np.ndarray:
    a = X[:, [0, 2]] if d.surface == "wall" else X[:, [0, 1]]
    return np.all((a >= d.lo) & (a <= d.hi), axis=1)


def _decal_color(d: Decal, X: np.ndarray) -> np.ndarray:
    a = X[:, [0, 2]] if d.surface == "wall" else X[:, [0, 1]]
    uv = (a - d.lo) / (d.hi - d.lo)
    c1, c2 = np.array(d.colors[0]), np.array(d.colors[1])
    if d.name == "poster":
        ring = np.hypot(uv[:, 0] - 0.35, uv[:, 1] - 0.55)
        w = ((np.floor(uv[:, 0] * 4) + np.floor(uv[:, 1] * 3)) % 2) * 0.6 + 0.4 * (np.sin(ring * 40) > 0)
        border = (np.minimum(uv, 1 - uv).min(1) < 0.06).astype(np.float64)
        alb = c1 * (1 - w[:, None]) + c2 * w[:, None]
        alb = alb * (1 - border[:, None]) + np.array([0.08, 0.08, 0.1]) * border[:, None]
    else:
        w = (np.abs((uv[:, 0] * 6) % 2 - 1) + np.abs((uv[:, 1] * 4) % 2 - 1) > 1).astype(np.float64)
        alb = c1 * (1 - w[:, None]) + c2 * w[:, None]
    n = np.tile([0.0, -1.0, 0.0] if d.surface == "wall" else [0.0, 0.0, 1.0], (len(X), 1))
    return alb * _light(n)[:, None]


def trace(spec: SceneSpec, cam: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ray origin, directions and the (primitives x rays) hit parameters of one view."""
    o, D = camera_rays(cam)
    return o, D, np.stack([_intersect(p, o, D) for p in spec.prims])


def _shade_rays(spec: SceneSpec, o: np.ndarray, D: np.ndarray, T: np.ndarray):
    """Colour, depth and instance of rays D given their (primitives x rays) hit parameters T."""
    idx = np.argmin(T, axis=0)
    t = T[idx, np.arange(len(D))]
    hit = np.isfinite(t)
    rgb = np.zeros((len(D), 3))
    inst = np.full(len(D), -1, np.int32)
    for k, p in enumerate(spec.prims):
        sel = hit & (idx == k)
        if not sel.any():
            continue
        X = o + t[sel, None] * D[sel]
        col = _shade(p, X)
        ins = np.full(len(X), p.instance, np.int32)
        for d in spec.decals:
            if d.surface == p.kind:
                m = _decal_mask(d, X)
                col[m] = _decal_color(d, X[m])
                ins[m] = d.instance
        rgb[sel] = col
        inst[sel] = ins
    return np.clip(rgb, 0, 1), np.where(hit, t, 0.0), inst


def render_view(spec: SceneSpec, cam: Camera, exclude: int | None = None, traced: tuple | None = None,
                base: dict | None = None) -> dict[str, np.ndarray]:
    """rgb (H,W,3 float32), depth (H,W float32, 0 = no surface), instances (H,W int32, -1 = none).

    `exclude`: an object instance left out (removal ground truth); `traced`: a cached `trace` of the
    view; `base`: the full render of the view, so that only the pixels the object covered are re-cast.
    """
    o, D, T = traced if traced is not None else trace(spec, cam)
    H, W = cam.height, cam.width
    if exclude is None:
        rgb, depth, inst = _shade_rays(spec, o, D, T)
    else:
        rows = [k for k, p in enumerate(spec.prims) if p.instance == exclude]
        if base is None:
            pix = np.arange(len(D))
            rgb, depth, inst = np.zeros((len(D), 3)), np.zeros(len(D)), np.full(len(D), -1, np.int32)
        else:
            pix = np.flatnonzero(base["instances"].ravel() == exclude)
            rgb = base["rgb"].reshape(-1, 3).astype(np.float64)
            depth = base["depth"].ravel().astype(np.float64)
            inst = base["instances"].ravel().copy()
        Ts = T[:, pix].copy()
        Ts[rows] = np.inf
        rgb[pix], depth[pix], inst[pix] = _shade_rays(spec, o, D[pix], Ts)
    return {"rgb": rgb.astype(np.float32).reshape(H, W, 3), "depth": depth.astype(np.float32).reshape(H, W),
            "instances": inst.reshape(H, W)}


# ------------------------------------------------------------------------------------ writing
def _sample_points(spec: SceneSpec, renders: list[dict], ids: list[int], n: int, rng: np.random.Generator):
    """Surface points back-projected from the GT depth of the given views, coloured by the image."""
    pts, cols = [], []
    per = max(1, n // max(len(ids), 1))
    for i in ids:
        cam, r = spec.cameras[i], renders[i]
        valid = np.flatnonzero(r["depth"].ravel() > 0)
        if not len(valid):
            continue
        pick = rng.choice(valid, size=min(per, len(valid)), replace=False)
        o, D = camera_rays(cam)
        pts.append(o + r["depth"].ravel()[pick, None] * D[pick])
        cols.append(r["rgb"].reshape(-1, 3)[pick])
    return np.concatenate(pts), np.concatenate(cols)


def _label_json(name: str, W: int, H: int, cmap: np.ndarray, classes: list[str], label_classes: list[str]) -> dict:
    objs = []
    group = 0
    for c in label_classes:
        m = cmap == classes.index(c)
        if not m.any():
            continue
        group += 1
        for poly in mask_to_polygons(m):
            pm = np.zeros((H, W), np.uint8)
            cv2.fillPoly(pm, [poly.reshape(-1, 1, 2)], 1)
            objs.append({"category": c, "group": group, "segmentation": poly.tolist(), "area": float(pm.sum()),
                         "layer": float(group), "bbox": [float(v) for v in (*poly.min(0), *poly.max(0))],
                         "iscrowd": 0, "note": ""})
    return {"info": {"name": name, "width": W, "height": H, "depth": 3, "note": "gsbench synthetic"}, "objects": objs}


def make_scene(preset: str, out: Path, seed: int = 0, views: int | None = None,
               resolution: tuple[int, int] | None = None, layout: str = "both", progress: bool = False) -> Path:
    """Render a preset into `out` (a new or empty folder). The folder appears whole (temp + rename)."""
    from tqdm import tqdm

    if layout not in LAYOUT_CHOICES:
        raise InputError(f"unknown layout {layout!r}; choose one of {', '.join(LAYOUT_CHOICES)}")
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise InputError(f"{out}: exists and is not an empty folder; choose another --out or remove it")
    spec = compose(preset, seed, views, resolution)
    rng = np.random.default_rng([seed, 1])
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        _write(spec, tmp, preset, preset, seed, layout, rng, progress, tqdm)
        if out.exists():
            out.rmdir()
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def _write(spec: SceneSpec, root: Path, scene_name: str, preset: str, seed: int, layout: str,
           rng: np.random.Generator, progress: bool, tqdm) -> None:
    cams = spec.cameras
    n = len(cams)
    names = [c.name for c in cams]
    stems = [Path(x).stem for x in names]
    W, H = cams[0].width, cams[0].height
    classes = spec.class_names
    lut = np.full(max(spec.instance_classes) + 2, -1, np.int32)
    for k, v in spec.instance_classes.items():
        lut[k] = v
    label_classes = [c for c in classes if c not in ("floor", "wall")]
    renders = []
    for i in tqdm(range(n), desc="make-scene", disable=not progress):
        traced = trace(spec, cams[i])
        r = render_view(spec, cams[i], traced=traced)
        renders.append({"rgb": r["rgb"], "depth": r["depth"]})
        write_png(root / "images" / names[i], r["rgb"], atomic=False)
        write_npy(root / "gt" / "depth" / f"{stems[i]}.npy", r["depth"], atomic=False)
        write_png(root / "gt" / "instances" / f"{stems[i]}.png", (r["instances"] + 1).astype(np.uint16), atomic=False)
        for inst in spec.removable:
            rr = render_view(spec, cams[i], exclude=inst, traced=traced, base=r)
            write_png(root / "gt" / "removal" / stems[i] / f"{inst:03d}.png", rr["rgb"], atomic=False)
        cmap = np.where(r["instances"] >= 0, lut[r["instances"]], -1)
        if layout in ("both", "3dovs"):
            for k, c in enumerate(classes):
                write_png(root / "segmentations" / f"{i:03d}" / f"{c}.png", np.where(cmap == k, 255, 0).astype(np.uint8),
                          atomic=False)
        if layout in ("both", "lerf"):
            write_json_atomic(root / "label" / scene_name / f"{stems[i]}.json",
                              _label_json(names[i], W, H, cmap, classes, label_classes))
    train = [i for i in range(n) if i % 8 != 0]
    test = [i for i in range(n) if i % 8 == 0]
    pts, cols = _sample_points(spec, renders, train, PRESETS[preset]["points"], rng)
    write_colmap(root / "sparse" / "0", cams, names, pts, cols, binary=True)
    if layout in ("both", "3dovs"):
        (root / "segmentations").mkdir(parents=True, exist_ok=True)
        (root / "segmentations" / "classes.txt").write_text("\n".join(classes) + "\n", encoding="utf-8")
        bounds = []
        for r in renders:
            d = r["depth"][r["depth"] > 0]
            bounds.append([0.9 * float(d.min()), 1.1 * float(d.max())] if d.size else [0.1, FAR])
        write_poses_bounds(root / "poses_bounds.npy", cams, np.array(bounds))
    all_d = np.concatenate([r["depth"][r["depth"] > 0] for r in renders])
    meta = {
        "format": "gsbench-synthetic", "version": GENERATOR_VERSION,
        "near": float(all_d.min()), "far": float(all_d.max()),
        "generator": {"preset": preset, "seed": seed, "views": n, "resolution": [W, H], "layout": layout},
        "image_names": names, "train_ids": train, "test_ids": test,
        "class_names": classes, "queries": label_classes,
        "instance_classes": {str(k): v for k, v in spec.instance_classes.items()},
        "instance_names": {str(k): v for k, v in spec.instance_names.items()},
        "removable_instances": spec.removable,
        "texture_only_classes": [d.name for d in spec.decals],
        "gt_dir": "gt",
        "depth": "gt/depth/<stem>.npy: float32 camera-space z, 0 where the ray hits nothing",
        "instances": "gt/instances/<stem>.png: uint16, instance id + 1, 0 = none",
        "removal": "gt/removal/<stem>/<id:03d>.png: RGB with object <id> removed",
        "cameras": [c.to_dict() for c in cams],
    }
    write_json_atomic(root / "gsbench_scene.json", meta)


def parse_resolution(text: str) -> tuple[int, int]:
    """'WxH' -> (W, H)."""
    try:
        w, h = text.lower().split("x")
        return int(w), int(h)
    except ValueError:
        raise InputError(f"--resolution must look like 128x96, got {text!r}") from None
