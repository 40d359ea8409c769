"""Synthetic scene specifications: presets, the object pool, and `compose` (a seeded layout of
primitives, decals and cameras). The ray caster (synthetic_render) draws a SceneSpec; synthetic
writes it to disk."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gsbench.camera import Camera
from gsbench.errors import InputError

WALL_Y = 1.0
FAR = 50.0
LAYOUT_CHOICES = ("both", "3dovs", "lerf")
GENERATOR_VERSION = 1

PRESETS: dict[str, dict] = {
    # tests and the demo: small enough for CPU training in minutes
    "tabletop-small": dict(
        objects=(4, 5),
        views=24,
        resolution=(128, 96),
        decals=("poster",),
        path="arc",
        arc_deg=110.0,
        elevation_deg=(24.0, 38.0),
        radius=(1.75, 2.0),
        hfov_deg=55.0,
        points=4000,
        area=(0.55, 0.4),
    ),
    # benchmarks: more objects, a second decal, hemisphere cameras
    "room-medium": dict(
        objects=(7, 8),
        views=60,
        resolution=(320, 240),
        decals=("poster", "rug"),
        path="hemisphere",
        arc_deg=150.0,
        elevation_deg=(18.0, 55.0),
        radius=(2.1, 2.6),
        hfov_deg=60.0,
        points=20000,
        area=(0.8, 0.55),
    ),
}

# studies on the CPU (the cpu-medium preset): the tabletop at 256x192, where the smallest objects are about
# 30 px across, so segmentation metrics are not capped by the resolution
PRESETS["tabletop-medium"] = dict(PRESETS["tabletop-small"], resolution=(256, 192))
# the latent-d control: every object of the pool in the room (10 objects + floor, wall and two decals =
# 14 classes, so 14 queries), at the CPU study scale
PRESETS["room-many"] = dict(PRESETS["room-medium"], objects=(10, 10), views=24, resolution=(256, 192))

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


def compose(
    preset: str, seed: int = 0, views: int | None = None, resolution: tuple[int, int] | None = None
) -> SceneSpec:
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
    n_obj = max(3, min(len(OBJECT_POOL), n_obj))
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
    prims.append(
        Prim("floor", "floor", n, colors=((0.74, 0.64, 0.50), (0.60, 0.50, 0.38)), pattern="checker", period=0.3)
    )
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
