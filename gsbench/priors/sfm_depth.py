"""The ``sfm`` depth prior: a weight-free relative disparity for real photos, from the scene's SfM points.

Real photos have no GT depth for the simulated prior, and a monocular model needs weights. What
every posed capture does have is its sparse points (`gsbench points` triangulates them). Per view:

1. Visibility. With the COLMAP tracks of the scene's model (a model COLMAP itself wrote), a point
   is used in the views its track names. Without tracks (the model `gsbench points` writes keeps
   none), a point-splat z-buffer test: a point is hidden when points nearer by more than
   ``OCCLUSION_TOL`` of its depth lie around it, within ``OCCLUSION_RADIUS_FRAC`` of the image
   diagonal, in at least ``OCCLUDER_QUADRANTS`` of the four quadrants. A surface in front covers
   the point from every side; a slanted surface's nearer side lies on one side only (without the
   quadrant rule the far parts of a floor, and the rims of a ball, hide behind their own near parts).
2. Densification, edge-aware: a confidence-weighted normalised convolution whose filter is
   OpenCV's fast global smoother (ximgproc, from opencv-contrib, already a dependency) guided by
   the photo, first order: at each pixel the plane in (x, y, disparity) that fits the points best,
   each point weighted by the smoother's weight between it and the pixel (FGS of the weighted
   moments, with d the points' disparity 1 / z splatted on their pixels and w = 1 there). A
   zero-order version, FGS(w d) / FGS(w), pulls slanted surfaces towards their inside points near
   the border and near edges. Disparity, not depth: over a plane it is affine in the pixel
   coordinates, so a plane comes out exact.
3. A consistency pass: points that lie behind the dense surface at their own pixel by more than
   ``OCCLUSION_TOL`` (hidden points step 1 missed) are dropped and step 2 is run again.
4. Validity: a pixel is valid where the filtered confidence FGS(w) is at least ``MIN_SUPPORT``
   of its mean over the image and a used point lies within ``MAX_GAP_FRAC`` of the diagonal.

The values are disparity divided by its median over the valid pixels (kind ``disparity``, like a
monocular estimator's output); invalid pixels are 0. Failure modes (docs/priors.md): textureless
regions have no points, so they are holes (invalid) or, when small, bridged from their borders;
occlusion edges follow the photo's edges, so an edge with no colour change is smoothed across;
thin structures with few points take the depth of what is behind them.
"""
from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial import cKDTree

from gsbench.camera import Camera
from gsbench.colmap_lib import import_pycolmap
from gsbench.datasets.colmap import find_model_dir
from gsbench.errors import InputError
from gsbench.priors.warp import NEAR

log = logging.getLogger(__name__)

SFM_VERSION = 1
OCCLUSION_RADIUS_FRAC = 0.025   # z-buffer test neighbourhood, share of the image diagonal
OCCLUSION_TOL = 0.05            # nearer by more than this share of the depth hides a point
OCCLUDER_QUADRANTS = 3          # quadrants around a point that must hold a nearer point to hide it
FGS_LAMBDA = 400.0              # fast global smoother: smoothness weight (larger fills larger gaps)
FGS_SIGMA_COLOR = 8.0           # fast global smoother: colour range (8-bit levels) of one edge
MIN_SUPPORT = 0.1               # valid where FGS(w) >= this share of the mean of w
MAX_GAP_FRAC = 0.08             # valid within this share of the image diagonal of a used point
RIDGE = 0.01 ** 2               # slope damping of the local planes (a share of the diagonal, squared)
MIN_POINTS = 3                  # fewer visible points than this give an empty (all invalid) prior


@dataclass
class ViewPoints:
    """The points one view sees: indices into the scene's points, pixel positions and camera z."""

    index: np.ndarray   # (M,) int
    uv: np.ndarray      # (M, 2) float, pixel centres at +0.5
    z: np.ndarray       # (M,) float, > 0


def point_tracks(scene) -> dict[int, np.ndarray] | None:
    """Per view, the indices of the points whose COLMAP track names that view; None without tracks.

    Point indices follow the scene's points (the model's points sorted by id, as the reader loads
    them). A model with any empty track (the one `gsbench points` writes) counts as one without."""
    model_dir = find_model_dir(Path(scene.path)) if scene.has_points else None
    if model_dir is None:
        return None
    pycolmap = import_pycolmap()

    rec = pycolmap.Reconstruction(str(model_dir))
    pts = sorted(rec.points3D.items())
    if len(pts) != len(scene.points) or any(p.track.length() == 0 for _, p in pts):
        return None
    view_of_name = {Path(p).name: i for i, p in enumerate(scene.image_paths)}
    view_of_image = {im_id: view_of_name.get(im.name) for im_id, im in rec.images.items()}
    seen: dict[int, list[int]] = {}
    for k, (_, p) in enumerate(pts):
        for e in p.track.elements:
            v = view_of_image.get(e.image_id)
            if v is not None:
                seen.setdefault(v, []).append(k)
    return {v: np.unique(np.asarray(ks, dtype=np.int64)) for v, ks in seen.items()}


def points_digest(scene) -> str:
    """sha256 of the scene's points and of its model's points file (their tracks): the scene
    fingerprint covers images and cameras only, so the ``sfm`` cache key adds this."""
    h = hashlib.sha256()
    if scene.has_points:
        h.update(np.ascontiguousarray(np.asarray(scene.points, dtype=np.float64)).tobytes())
    model_dir = find_model_dir(Path(scene.path)) if scene.path else None
    for name in ("points3D.bin", "points3D.txt"):
        if model_dir is not None and (model_dir / name).is_file():
            h.update((model_dir / name).read_bytes())
    return h.hexdigest()


def project_points(points: np.ndarray, cam: Camera, subset: np.ndarray | None = None) -> ViewPoints:
    """The points (or the `subset` indices of them) that land in `cam`'s image in front of it."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    idx = np.arange(len(pts)) if subset is None else np.asarray(subset, dtype=np.int64)
    idx = idx[np.isfinite(pts[idx]).all(axis=1)]
    uv, z = cam.project(pts[idx])
    ok = (np.isfinite(uv).all(axis=1) & np.isfinite(z) & (z > NEAR)
          & (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height))
    return ViewPoints(idx[ok], uv[ok], z[ok])


def hidden_by_neighbours(vp: ViewPoints, size: tuple[int, int]) -> np.ndarray:
    """Bool (M,): the points hidden by nearer points around them (the z-buffer test of the module doc)."""
    hidden = np.zeros(len(vp.z), dtype=bool)
    if len(vp.z) <= OCCLUDER_QUADRANTS:
        return hidden
    radius = OCCLUSION_RADIUS_FRAC * float(np.hypot(*size))
    tree = cKDTree(vp.uv)
    for i, nb in enumerate(tree.query_ball_point(vp.uv, radius)):
        nb = np.asarray(nb, dtype=np.int64)
        nb = nb[vp.z[nb] < vp.z[i] * (1.0 - OCCLUSION_TOL)]
        if len(nb) < OCCLUDER_QUADRANTS:
            continue
        d = vp.uv[nb] - vp.uv[i]
        quadrant = (d[:, 0] >= 0).astype(np.int64) + 2 * (d[:, 1] >= 0).astype(np.int64)
        hidden[i] = len(np.unique(quadrant)) >= OCCLUDER_QUADRANTS
    return hidden


def visible_points(points: np.ndarray, cam: Camera, track: np.ndarray | None = None) -> ViewPoints:
    """The points `cam` sees: its `track` points when the model has tracks, else the z-buffer test's."""
    if track is not None:
        return project_points(points, cam, track)
    vp = project_points(points, cam)
    keep = ~hidden_by_neighbours(vp, (cam.width, cam.height))
    return ViewPoints(vp.index[keep], vp.uv[keep], vp.z[keep])


def _guide(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """The photo as the 8-bit 3-channel guide at `size` (area-resized)."""
    img = np.asarray(image, dtype=np.float32)[..., :3]
    if img.shape[1] != size[0] or img.shape[0] != size[1]:
        img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(np.clip(np.rint(np.nan_to_num(img) * 255.0), 0, 255).astype(np.uint8))


def _splat(uv: np.ndarray, disp: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Mean disparity of the points on each pixel and the points' weight (1 where any point lands)."""
    W, H = size
    pix = np.floor(uv[:, 1]).astype(np.int64) * W + np.floor(uv[:, 0]).astype(np.int64)
    total = np.bincount(pix, weights=disp, minlength=W * H)
    count = np.bincount(pix, minlength=W * H).astype(np.float64)
    mean = np.divide(total, count, out=np.zeros_like(total), where=count > 0)
    return mean.reshape(H, W), (count > 0).reshape(H, W).astype(np.float64)


def _smooth(guide: np.ndarray, x: np.ndarray) -> np.ndarray:
    if not hasattr(cv2, "ximgproc"):
        # opencv-python(-headless) installed beside or after opencv-contrib-python-headless shadows it
        raise InputError(f"priors.depth.provider=sfm needs OpenCV's contrib module ximgproc, which the cv2 at "
                         f"{getattr(cv2, '__file__', '?')} lacks: pip uninstall opencv-python opencv-python-headless, "
                         f"then pip install --force-reinstall opencv-contrib-python-headless")
    return cv2.ximgproc.fastGlobalSmootherFilter(guide, x.astype(np.float32), FGS_LAMBDA, FGS_SIGMA_COLOR
                                                 ).astype(np.float64)


def _local_affine(guide: np.ndarray, d: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First-order normalised convolution: at every pixel p, the weighted least-squares plane
    a + b (x - x_p) + c (y - y_p) through the splatted disparities `d` (weights `w`), the weights
    being the smoother's own (it is linear in its input for one guide). Returns (a, FGS(w)).

    Coordinates are in image diagonals, centred on the image; slopes are damped by RIDGE (a share of
    the diagonal, squared) where the points around p are too few or in a line to fix a plane."""
    H, W = d.shape
    diag = float(np.hypot(H, W))
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    x, y = (xs - W / 2) / diag, (ys - H / 2) / diag
    ref = float(np.sum(d * w) / max(float(w.sum()), 1e-12))   # moments of d - ref: less cancellation
    dd = np.where(w > 0, d - ref, 0.0)
    m = {k: _smooth(guide, w * f) for k, f in (("1", 1.0), ("x", x), ("y", y), ("xx", x * x), ("xy", x * y),
                                               ("yy", y * y), ("d", dd), ("xd", x * dd), ("yd", y * dd))}
    s0 = m["1"]
    sx, sy = m["x"] - x * s0, m["y"] - y * s0
    sxx = m["xx"] - 2 * x * m["x"] + x * x * s0 + RIDGE * s0
    syy = m["yy"] - 2 * y * m["y"] + y * y * s0 + RIDGE * s0
    sxy = m["xy"] - x * m["y"] - y * m["x"] + x * y * s0
    sxd, syd = m["xd"] - x * m["d"], m["yd"] - y * m["d"]
    # a by Cramer's rule on the symmetric 3 x 3 system [[s0 sx sy] [sx sxx sxy] [sy sxy syy]] (a b c) = (d xd yd)
    c00, c01, c02 = sxx * syy - sxy * sxy, sxy * sy - sx * syy, sx * sxy - sxx * sy
    det = s0 * c00 + sx * c01 + sy * c02
    num = m["d"] * c00 + sxd * c01 + syd * c02
    tiny = np.abs(det) <= 1e-12 * np.maximum(s0, 1e-300) ** 3     # no plane: the weighted mean instead
    a = np.divide(num, det, out=np.zeros_like(num), where=~tiny)
    a = np.where(tiny, np.divide(m["d"], s0, out=np.zeros_like(s0), where=s0 > 0), a)
    return a + ref, s0


def densify(uv: np.ndarray, disp: np.ndarray, guide: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Edge-aware first-order normalised convolution of sparse disparities at pixels `uv`: (dense, valid).

    First order (a local plane at each pixel, not a local mean) so that a slanted surface keeps its
    slope up to the image border and up to an edge, where a smoothed mean pulls towards the points
    on the inside. `guide` is the 8-bit photo (H, W, 3); `dense` is 0 where not valid."""
    H, W = guide.shape[:2]
    if len(disp) < MIN_POINTS:
        return np.zeros((H, W)), np.zeros((H, W), dtype=bool)
    d, w = _splat(uv, disp, (W, H))
    dense, den = _local_affine(guide, d, w)
    floor = MIN_SUPPORT * float(w.mean())
    gap = cv2.distanceTransform((w == 0).astype(np.uint8), cv2.DIST_L2, 5)
    valid = (den >= floor) & (den > 0) & (gap <= MAX_GAP_FRAC * float(np.hypot(H, W)))
    valid &= np.isfinite(dense) & (dense > 0)
    return np.where(valid, dense, 0.0), valid


def behind_surface(vp: ViewPoints, dense: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Bool (M,): points behind the dense disparity at their pixel by more than OCCLUSION_TOL."""
    ix = np.floor(vp.uv[:, 0]).astype(np.int64)
    iy = np.floor(vp.uv[:, 1]).astype(np.int64)
    surface = dense[iy, ix]
    return valid[iy, ix] & (1.0 / vp.z < surface * (1.0 - OCCLUSION_TOL))


def sfm_disparity(vp: ViewPoints, image: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """One view's prior at `size` = (W, H) from its visible points `vp` (pixels at that size) and its
    photo (any size): (values float32, valid)."""
    guide = _guide(image, size)
    dense, valid = densify(vp.uv, 1.0 / vp.z, guide)
    if valid.any():
        keep = ~behind_surface(vp, dense, valid)
        if not keep.all():
            dense, valid = densify(vp.uv[keep], 1.0 / vp.z[keep], guide)
    if not valid.any():
        return np.zeros(dense.shape, np.float32), valid
    med = float(np.median(dense[valid]))
    dense = dense / med if med > 0 else dense
    return dense.astype(np.float32), valid


def sfm_depth_prior(points: np.ndarray, cam: Camera, image: np.ndarray, track: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The ``sfm`` prior of one view: `cam` at the prior's size, `image` the view's photo (any size)."""
    vp = visible_points(points, cam, track)
    if len(vp.z) < MIN_POINTS:
        log.warning("sfm depth prior: view %s sees %d points, fewer than %d: its prior is empty",
                    cam.name or "?", len(vp.z), MIN_POINTS)
    return sfm_disparity(vp, image, (cam.width, cam.height))


def visibility_source(tracks: dict | None) -> str:
    """How the points' visibility was decided, for the provider id."""
    return "tracks" if tracks is not None else "zbuffer"
