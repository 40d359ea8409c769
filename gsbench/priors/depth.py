"""Depth-prior providers. Every prior is at the training resolution `size` = (W, H).

- ``gt`` (weight-free, synthetic scenes): the scene's GT depth turned into a disparity-like prior
  the way a monocular estimator makes one. Inverse depth, normalised by its median (invalid pixels
  count as disparity 0, like sky), is resampled to the estimator's working size (short side
  ``working_size``, default WORKING_SIZE = 518 as Depth Anything's input; the aspect ratio kept),
  where its edges are smeared by a Gaussian blur of EDGE_SIGMA_PX working pixels; the result is
  resized bicubically to `size`, as a real pipeline upsamples its prediction. Edges are thus a few
  working pixels wide at any output size. Then a random per-view scale (log-uniform in
  ``GT_SCALE_RANGE``) and shift (uniform in ``GT_SHIFT_RANGE``) seeded by (seed, view id). The
  scale and shift differ per view, so the loss's scale-shift alignment is genuinely needed.
  ``distortion`` (severity >= 0, default 1) adds what a scale-shift fit cannot remove, as
  monocular estimators do: a low-frequency per-view multiplicative warp of the disparity,
  exp(DIST_PER_SEVERITY * severity * f) with f a smooth unit-std field (a DIST_GRID random grid
  upsampled bicubically), and extra edge smearing (the blur sigma grows by SMEAR_PX_PER_SEVERITY
  working pixels per severity, at most MAX_SIGMA_FRAC of the working short side). Severity 0 is
  the plain scale-shift model. Kind ``disparity``; valid where the GT depth (nearest-resized to
  `size`) is.
- ``sparse``: the scene's sparse points projected into each view with a z-buffer (nearest point
  per pixel). Kind ``depth``; valid only at pixels a point lands on. There are no per-point
  visibility tracks, so a point behind a surface that has no points of its own can show through.
- ``sfm`` (weight-free, real photos): the sparse points, with a visibility test, densified by an
  edge-aware filter guided by the photo (`gsbench.priors.sfm_depth`). Kind ``disparity`` (relative);
  valid where points support it. The recorded id ends in ``+tracks`` or ``+zbuffer`` (visibility).
- ``depth-anything``: Depth Anything through transformers (AutoModelForDepthEstimation and its
  image processor) from a local model folder, never downloading. It sees the full-resolution
  image; its relative-disparity output is resized bicubically to `size`. Kind ``disparity``.
- ``auto``: the first of these the scene can feed: ``gt`` where it has GT depth (the synthetic
  scenes: exactly what ``gt`` computes there, same id and cache entry), else ``sfm`` where it has
  sparse points, else ``depth-anything`` where ``model_path`` names local weights, else no prior
  (`auto_depth_provider`). The recorded provider reads ``auto -> <id>``.
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

from gsbench.config import check_key, get_dotted, setting
from gsbench.config_keys import DEPTH_PROVIDERS
from gsbench.datasets.noise import apply_noise
from gsbench.device import default_device
from gsbench.errors import InputError
from gsbench.priors import sfm_depth as SFM
from gsbench.priors import warp as W
from gsbench.priors.weights import require_weights
from gsbench.resize import resize_nearest

DEPTH_KINDS = ("disparity", "depth", "metric")
WORKING_SIZE = 518          # short side of the simulated estimator's working image (pixels)
EDGE_SIGMA_PX = 0.5         # edge blur at severity 0, in working pixels (see docs/priors.md)
SMEAR_PX_PER_SEVERITY = 0.5  # extra edge blur per unit of distortion, in working pixels
MAX_SIGMA_FRAC = 0.1        # the blur's cap, as a share of the working short side
GT_SCALE_RANGE = (0.5, 2.0)
GT_SHIFT_RANGE = (0.0, 0.5)
GT_VERSION = 3              # 3: blur and distortion at the working size, bicubic to the output size
DIST_PER_SEVERITY = 0.1
DIST_GRID = (3, 4)
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


def working_shape(shape: tuple[int, int], short_side: int = WORKING_SIZE) -> tuple[int, int]:
    """(H, W) of the estimator's working image for an image of `shape` (H, W): short side
    `short_side`, the aspect ratio kept."""
    H, Wd = int(shape[0]), int(shape[1])
    if H < 1 or Wd < 1:
        raise ValueError(f"working_shape: empty image shape {shape}")
    k = float(short_side) / min(H, Wd)
    return max(1, int(round(H * k))), max(1, int(round(Wd * k)))


def resample_disparity(disp: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """`disp` at `shape` (H, W): area averaging when shrinking (a resized input image's edges are one
    pixel wide), bilinear when enlarging, unchanged at the same shape."""
    H, Wd = shape
    if disp.shape == (H, Wd):
        return disp
    shrink = H * Wd < disp.shape[0] * disp.shape[1]
    return cv2.resize(disp, (Wd, H), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)


def gt_disparity_prior(depth: np.ndarray, rng: np.random.Generator, distortion: float = 0.0,
                       size: tuple[int, int] | None = None, working_size: int = WORKING_SIZE
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Estimator-like disparity at `size` (W, H; default the depth's) from a GT z map (see module
    doc): (values float32, valid bool)."""
    z = np.asarray(depth, dtype=np.float64)
    Wo, Ho = (z.shape[1], z.shape[0]) if size is None else (int(size[0]), int(size[1]))
    ok = np.isfinite(z) & (z > W.NEAR)
    zo = resize_nearest(z, Wo, Ho)
    valid = np.isfinite(zo) & (zo > W.NEAR)
    if not ok.any() or not valid.any():
        return np.zeros((Ho, Wo), np.float32), valid
    disp = np.zeros_like(z)
    disp[ok] = 1.0 / z[ok]
    med = float(np.median(disp[ok]))
    disp /= med if med > 0 else 1.0
    work = working_shape(z.shape, working_size)
    disp = resample_disparity(disp, work)
    sigma = min(MAX_SIGMA_FRAC * min(work), EDGE_SIGMA_PX + SMEAR_PX_PER_SEVERITY * distortion)
    disp = cv2.GaussianBlur(disp, (0, 0), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REPLICATE)
    lo, hi = np.log(GT_SCALE_RANGE[0]), np.log(GT_SCALE_RANGE[1])
    scale = float(np.exp(rng.uniform(lo, hi)))
    shift = float(rng.uniform(*GT_SHIFT_RANGE))
    field = smooth_field(work, rng)               # drawn always: the knob does not shift the stream
    disp = disp * np.exp(np.clip(DIST_PER_SEVERITY * distortion * field, -20.0, 20.0))
    if disp.shape != (Ho, Wo):                    # the prediction resized as a real pipeline does it
        disp = cv2.resize(disp, (Wo, Ho), interpolation=cv2.INTER_CUBIC)
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


def working_size_of(depth_cfg: Mapping) -> int:
    """The `priors.depth.working_size` (short side in pixels) of the gt provider (default.yaml's if unset)."""
    key = "priors.depth.working_size"
    return int(check_key(key, depth_cfg["working_size"] if "working_size" in depth_cfg else setting({}, key)))


def auto_depth_provider(depth_cfg: Mapping, scene) -> tuple[str | None, str]:
    """What ``auto`` resolves to on `scene`: (provider, '') or (None, why no prior). GT depth first (the
    synthetic scenes), then the sparse points (`sfm`), then a depth model from local weights
    (`depth-anything`, only when `model_path` is set: nothing is downloaded)."""
    if scene.has_depth:
        return "gt", ""
    if scene.has_points:
        return "sfm", ""
    if depth_cfg.get("model_path"):
        return "depth-anything", ""
    return None, ("priors.depth.provider=auto: the scene has no GT depth and no sparse points (`gsbench points "
                  "SCENE` triangulates them), and priors.depth.model_path names no depth model")


def asks_depth_rule(config: Mapping) -> bool:
    """Whether the config's depth provider is the rule ``auto``, which needs the scene to settle."""
    try:
        depth_cfg = get_dotted(config, "priors.depth")
    except KeyError:
        return False
    return isinstance(depth_cfg, Mapping) and depth_cfg.get("provider") == "auto"


def settle_depth_rule(config: dict, scene) -> dict:
    """`config` with its `resolved` section naming what ``priors.depth.provider: auto`` chooses on `scene`
    (gsbench.config.SCENE_RESOLVED_KEYS): the run id is then the concrete provider's, so `auto` on a
    synthetic scene is the same run, with the same id, as `gt`. Any other provider: `config` unchanged.
    Called where a config first meets its scene (training, grid planning), before its id is taken."""
    if not asks_depth_rule(config):
        return config
    depth_cfg = get_dotted(config, "priors.depth")
    chosen, _why = auto_depth_provider(depth_cfg, scene)
    out = dict(config)
    out["resolved"] = {**(config.get("resolved") or {}), "priors.depth.provider": chosen or "none"}
    return out


def resolved_depth_cfg(depth_cfg: Mapping, scene) -> tuple[dict, str]:
    """`depth_cfg` with ``auto`` replaced by the provider it resolves to on `scene` (``none`` when there
    is none, with the reason); any other provider as it is, with ''."""
    out = dict(depth_cfg)
    if out.get("provider") != "auto":
        return out, ""
    prov, why = auto_depth_provider(out, scene)
    out["provider"] = prov or "none"
    return out, why


def depth_provider_id(depth_cfg: Mapping) -> str | None:
    """The id recorded in results (before noise); None for ``none``. Real ids need the model."""
    p = depth_cfg.get("provider", "gt")
    if p in (None, "none"):
        return None
    if p == "gt":
        return f"gt-sim-disparity-v{GT_VERSION}:d{distortion_of(depth_cfg):g}:w{working_size_of(depth_cfg)}"
    if p == "sparse":
        return f"sparse-points-v{SPARSE_VERSION}"
    if p == "sfm":
        return f"sfm-fgs-v{SFM.SFM_VERSION}"
    if p == "depth-anything":
        mp = depth_cfg.get("model_path")
        return f"depth-anything:{Path(mp).resolve().name if mp else '?'}"
    raise InputError(f"priors.depth.provider: unknown provider {p!r} (expected one of {', '.join(DEPTH_PROVIDERS)})")


def compute_depth(scene, depth_cfg: Mapping, view_ids: Sequence[int], size: tuple[int, int],
                  seed: int = 0, progress: bool = False, device: str | None = None) -> dict[int, DepthPrior]:
    """Clean depth priors for `view_ids` at `size` (no noise; see `apply_depth_noise`); a depth model
    runs on `device` (the run's training device; None = CUDA when available, else the CPU). ``auto`` is
    first resolved for the scene (`resolved_depth_cfg`)."""
    depth_cfg, _ = resolved_depth_cfg(depth_cfg, scene)
    p = depth_cfg.get("provider", "gt")
    pid = depth_provider_id(depth_cfg)
    out: dict[int, DepthPrior] = {}
    bar = lambda it: tqdm(it, desc=f"depth prior ({p})", disable=not progress, leave=False)  # noqa: E731
    if p == "gt":
        if not scene.has_depth:
            raise InputError(f"{scene.path}: priors.depth.provider=gt needs GT depth and the scene has none "
                             "(use sparse or depth-anything)")
        distortion, working = distortion_of(depth_cfg), working_size_of(depth_cfg)
        for v in bar(view_ids):   # from the full-size GT depth: the estimator sees the full image
            vals, valid = gt_disparity_prior(scene.gt_depth(v), view_rng(seed, v, "gt-depth"), distortion,
                                             size, working)
            out[v] = DepthPrior(vals, valid, "disparity", pid)
    elif p == "sparse":
        if not scene.has_points:
            raise InputError(f"{scene.path}: priors.depth.provider=sparse needs sparse points and the scene has none")
        for v in bar(view_ids):
            vals, valid = sparse_depth_prior(scene.points, W.camera_at(scene.cameras[v], size))
            out[v] = DepthPrior(vals, valid, "depth", pid)
    elif p == "sfm":
        if not scene.has_points:
            raise InputError(f"{scene.path}: priors.depth.provider=sfm needs sparse points and the scene has none "
                             "(run `gsbench points` on it)")
        tracks = SFM.point_tracks(scene)
        sid = f"{pid}+{SFM.visibility_source(tracks)}"
        for v in bar(view_ids):
            track = None if tracks is None else tracks.get(v, np.zeros(0, np.int64))
            vals, valid = SFM.sfm_depth_prior(scene.points, W.camera_at(scene.cameras[v], size), scene.image(v),
                                              track)
            out[v] = DepthPrior(vals, valid, "disparity", sid)
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
