"""Depth-prior providers. Every prior is at the training resolution `size` = (W, H).

- ``gt`` (weight-free, synthetic scenes): the scene's GT depth turned into a disparity-like prior
  the way a monocular estimator sees it: inverse depth normalised by its median, edges smeared
  by a Gaussian blur (sigma = ``GT_BLUR_FRAC`` of the image diagonal, at least 0.5 px; invalid
  pixels count as disparity 0, like sky), then a random per-view scale (log-uniform in
  ``GT_SCALE_RANGE``) and shift (uniform in ``GT_SHIFT_RANGE``) seeded by (seed, view id). The
  scale and shift differ per view, so the loss's scale-shift alignment is genuinely needed.
  ``distortion`` (severity >= 0, default 1) adds what a scale-shift fit cannot remove, as
  monocular estimators do: a low-frequency per-view multiplicative warp of the disparity,
  exp(DIST_PER_SEVERITY * severity * f) with f a smooth unit-std field (a DIST_GRID random grid
  upsampled bicubically), and extra edge smearing (blur sigma grows by SMEAR_PER_SEVERITY of the
  diagonal per severity, at most one diagonal). Severity 0 is the plain scale-shift model.
  Kind ``disparity``; valid where the GT depth is.
- ``sparse``: the scene's sparse points projected into each view with a z-buffer (nearest point
  per pixel). Kind ``depth``; valid only at pixels a point lands on. There are no per-point
  visibility tracks, so a point behind a surface that has no points of its own can show through.
- ``depth-anything``: Depth Anything through transformers (AutoModelForDepthEstimation and its
  image processor) from a local model folder, never downloading. It sees the full-resolution
  image; its relative-disparity output is resized bicubically to `size`. Kind ``disparity``.
- ``none``: no prior.

Noise (the depth-noise study): `apply_depth_noise` applies
`gsbench.datasets.noise.apply_noise` to the prior only, after the cache (clean priors are cached).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import cv2
import numpy as np
from tqdm.auto import tqdm

from gsbench.config import check_key
from gsbench.datasets.noise import apply_noise
from gsbench.device import default_device
from gsbench.errors import InputError
from gsbench.priors import warp as W
from gsbench.priors.weights import require_weights
from gsbench.resize import resize_nearest

DEPTH_PROVIDERS = ("gt", "sparse", "depth-anything", "none")
DEPTH_KINDS = ("disparity", "depth", "metric")
GT_BLUR_FRAC = 0.005
GT_SCALE_RANGE = (0.5, 2.0)
GT_SHIFT_RANGE = (0.0, 0.5)
GT_VERSION = 2
DIST_PER_SEVERITY = 0.1
DIST_GRID = (3, 4)
SMEAR_PER_SEVERITY = 0.004
SPARSE_VERSION = 1
DA_VERSION = 1


@dataclass
class DepthPrior:
    """One view's depth prior: values (H, W) float32, valid (H, W) bool, kind, provider id."""

    values: np.ndarray
    valid: np.ndarray
    kind: str
    provider: str

    def __post_init__(self) -> None:
        if self.kind not in DEPTH_KINDS:
            raise ValueError(f"DepthPrior.kind must be one of {DEPTH_KINDS}, got {self.kind!r}")
        if self.values.shape != self.valid.shape:
            raise ValueError(f"DepthPrior: values {self.values.shape} and valid {self.valid.shape} differ")


def view_rng(seed: int, view: int, salt: str) -> np.random.Generator:
    """A generator that depends only on (seed, view, salt): stable across runs and orderings."""
    h = hashlib.sha256(f"{salt}:{int(seed)}:{int(view)}".encode()).digest()
    return np.random.default_rng(int.from_bytes(h[:8], "little"))


def smooth_field(shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """A low-frequency field with zero mean and unit std (DIST_GRID noise, bicubic upsampling)."""
    H, Wd = shape
    f = cv2.resize(rng.standard_normal(DIST_GRID), (Wd, H), interpolation=cv2.INTER_CUBIC).astype(np.float64)
    f -= f.mean()
    sd = float(f.std())
    return f / sd if sd > 1e-12 else f


def gt_disparity_prior(depth: np.ndarray, rng: np.random.Generator, distortion: float = 0.0
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Estimator-like disparity from a GT z map (see module doc): (values float32, valid bool)."""
    z = np.asarray(depth, dtype=np.float64)
    valid = np.isfinite(z) & (z > W.NEAR)
    if not valid.any():
        return np.zeros(z.shape, np.float32), valid
    disp = np.zeros_like(z)
    disp[valid] = 1.0 / z[valid]
    med = float(np.median(disp[valid]))
    disp /= med if med > 0 else 1.0
    H, Wd = z.shape
    diag = float(np.hypot(H, Wd))
    sigma = min(diag, max(0.5, GT_BLUR_FRAC * diag + SMEAR_PER_SEVERITY * distortion * diag))
    disp = cv2.GaussianBlur(disp, (0, 0), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REPLICATE)
    lo, hi = np.log(GT_SCALE_RANGE[0]), np.log(GT_SCALE_RANGE[1])
    scale = float(np.exp(rng.uniform(lo, hi)))
    shift = float(rng.uniform(*GT_SHIFT_RANGE))
    field = smooth_field((H, Wd), rng)            # drawn always: the knob does not shift the stream
    disp = disp * np.exp(np.clip(DIST_PER_SEVERITY * distortion * field, -20.0, 20.0))
    return (scale * disp + shift).astype(np.float32), valid


def sparse_depth_prior(points: np.ndarray, cam) -> tuple[np.ndarray, np.ndarray]:
    """z-buffered projection of points into `cam`: (z map float32 (0 invalid), valid bool)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    pc = pts @ cam.world_to_camera[:3, :3].T + cam.world_to_camera[:3, 3]
    _, zmap = W.zbuffer_splat(pts, pc[:, 2].astype(np.float64), cam, fill=np.float64(0.0))
    valid = np.isfinite(zmap)
    return np.where(valid, zmap, 0.0).astype(np.float32), valid


class DepthAnything:
    """Depth Anything (transformers) from a local folder; relative disparity output."""

    def __init__(self, model_path: str | None, device: str | None = None):
        require_weights("priors.depth.model_path", model_path, "Depth Anything",
                        "priors.depth.provider=depth-anything", folder=True)
        try:
            from transformers import AutoImageProcessor, AutoModelForDepthEstimation
        except ImportError as e:
            raise InputError(f"priors.depth.provider=depth-anything needs the `models` extra "
                             f"(pip install -e .[models]): {e}") from None
        try:
            self.processor = AutoImageProcessor.from_pretrained(model_path, local_files_only=True)
            self.model = AutoModelForDepthEstimation.from_pretrained(model_path, local_files_only=True)
        except (OSError, ValueError) as e:
            raise InputError(f"priors.depth.model_path: {model_path} is not a loadable Depth Anything "
                             f"folder (Depth Anything weights are needed for --set "
                             f"priors.depth.provider=depth-anything): {e}") from None
        device = device or default_device()
        self.model = self.model.to(device).float().eval()
        self.device = device
        self.id = f"depth-anything:{Path(model_path).resolve().name}"

    def predict(self, image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """Relative disparity (H, W) float32 at `size` = (W, H) for a float RGB image in [0, 1]."""
        import torch
        u8 = np.clip(np.rint(np.asarray(image)[..., :3] * 255), 0, 255).astype(np.uint8)
        inputs = self.processor(images=u8, return_tensors="pt")
        inputs = {k: v.to(self.device) for k, v in inputs.items()}
        with torch.inference_mode():
            pred = self.model(**inputs).predicted_depth            # (1, h, w)
            pred = torch.nn.functional.interpolate(pred[:, None].float(), size=(size[1], size[0]),
                                                   mode="bicubic", align_corners=False)[0, 0]
        return pred.cpu().numpy().astype(np.float32)


def distortion_of(depth_cfg: Mapping) -> float:
    """The `priors.depth.distortion` severity (>= 0) of the gt provider."""
    return float(check_key("priors.depth.distortion", depth_cfg.get("distortion", 1.0)))


def depth_provider_id(depth_cfg: Mapping) -> str | None:
    """The id recorded in results (before noise); None for ``none``. Real ids need the model."""
    p = depth_cfg.get("provider", "gt")
    if p in (None, "none"):
        return None
    if p == "gt":
        return f"gt-sim-disparity-v{GT_VERSION}:d{distortion_of(depth_cfg):g}"
    if p == "sparse":
        return f"sparse-points-v{SPARSE_VERSION}"
    if p == "depth-anything":
        mp = depth_cfg.get("model_path")
        return f"depth-anything:{Path(mp).resolve().name if mp else '?'}"
    raise InputError(f"priors.depth.provider: unknown provider {p!r} (expected one of {', '.join(DEPTH_PROVIDERS)})")


def compute_depth(scene, depth_cfg: Mapping, view_ids: Sequence[int], size: tuple[int, int],
                  seed: int = 0, progress: bool = False, device: str | None = None) -> dict[int, DepthPrior]:
    """Clean depth priors for `view_ids` at `size` (no noise; see `apply_depth_noise`); a depth model
    runs on `device` (the run's training device; None = CUDA when available, else the CPU)."""
    p = depth_cfg.get("provider", "gt")
    pid = depth_provider_id(depth_cfg)
    out: dict[int, DepthPrior] = {}
    bar = lambda it: tqdm(it, desc=f"depth prior ({p})", disable=not progress, leave=False)  # noqa: E731
    if p == "gt":
        if not scene.has_depth:
            raise InputError(f"{scene.path}: priors.depth.provider=gt needs GT depth and the scene has none "
                             "(use sparse or depth-anything)")
        distortion = distortion_of(depth_cfg)
        for v in bar(view_ids):
            z = resize_nearest(np.asarray(scene.gt_depth(v), dtype=np.float32), *size)
            vals, valid = gt_disparity_prior(z, view_rng(seed, v, "gt-depth"), distortion)
            out[v] = DepthPrior(vals, valid, "disparity", pid)
    elif p == "sparse":
        if not scene.has_points:
            raise InputError(f"{scene.path}: priors.depth.provider=sparse needs sparse points and the scene has none")
        for v in bar(view_ids):
            vals, valid = sparse_depth_prior(scene.points, W.camera_at(scene.cameras[v], size))
            out[v] = DepthPrior(vals, valid, "depth", pid)
    elif p == "depth-anything":
        model = DepthAnything(depth_cfg.get("model_path"), device)
        for v in bar(view_ids):
            vals = model.predict(scene.image(v), size)
            out[v] = DepthPrior(vals, np.isfinite(vals), "disparity", model.id)
    elif p in (None, "none"):
        return {}
    else:  # pragma: no cover - depth_provider_id raised already
        raise InputError(f"priors.depth.provider: unknown provider {p!r}")
    return out


def noise_suffix(noise_cfg: Mapping | None) -> str:
    """'' when no noise is configured, else '+noise:<type>:s<severity>' for the provider id."""
    if not noise_cfg or not noise_cfg.get("type"):
        return ""
    return f"+noise:{noise_cfg['type']}:s{int(noise_cfg.get('severity', 0))}"


def apply_depth_noise(priors: Mapping[int, DepthPrior], noise_cfg: Mapping | None, seed: int = 0
                      ) -> dict[int, DepthPrior]:
    """The priors with `gsbench.datasets.noise.apply_noise` applied per view (depth prior only)."""
    if not noise_cfg or not noise_cfg.get("type"):
        return dict(priors)
    kind = str(noise_cfg["type"])
    severity = int(noise_cfg.get("severity", 0))
    suffix = noise_suffix(noise_cfg)
    out = {}
    for v, p in priors.items():
        vals, valid = apply_noise(p.values, p.valid, kind, severity,
                                  int(view_rng(seed, v, "depth-noise").integers(2**31 - 1)))
        out[v] = DepthPrior(np.asarray(vals, dtype=np.float32), np.asarray(valid, dtype=bool),
                            p.kind, p.provider + suffix)
    return out
