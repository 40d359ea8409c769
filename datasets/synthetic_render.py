"""The analytic ray caster of the synthetic scenes (numpy): ray-primitive intersection, procedural
textures, Lambertian shading; RGB, depth and instance maps of a view, with or without one object."""
from __future__ import annotations

import math

import numpy as np

from gsbench.camera import Camera

from .synthetic_spec import AMBIENT, FAR, LIGHTS, WALL_Y, Decal, Prim, SceneSpec


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
            ts = np.where(
                (disc >= 0) & (a > 1e-12), (-b - np.sqrt(np.maximum(disc, 0))) / (2 * np.maximum(a, 1e-12)), np.inf
            )
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
