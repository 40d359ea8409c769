"""Feature providers: 512-d unit vectors per mask and per text query (one shared space).

- ``text-aligned`` (weight-free, CLIP-like, for scenes with labels): text and image
  vectors live in `gsbench.priors.clipspace` (CLIP's narrow cone and modality gap). A mask's
  vector is computed from what the mask covers, as CLIP sees a crop: the pixel-weighted mix of
  the GT classes inside the mask (3D-OVS classes, a synthetic scene's instance classes, or LERF
  label categories: `named_class_map`; a view without labels gets no mask feature; pixels with
  no class count as background), plus a share
  ``context`` of the classes in the ring around it (its bounding box grown by half its size,
  minus the mask: the crop's surroundings), plus a per-mask noise direction of weight ``noise``
  seeded by (seed, view, the mask's pixels). A leaking or merged mask gets a blended vector, and one
  object gets different vectors in different views. Text queries map to `clipspace.text_vector`.
- ``openclip``: OpenCLIP ViT-B/16 from a local checkpoint, never downloading. A mask's crop:
  background blacked out, cropped to the mask's bounding box, padded to a square with black,
  then the model's own preprocessing (resize to 224 x 224, CLIP normalisation). L2-normalised.
"""
from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from gsbench.config_keys import FEATURE_PROVIDERS
from gsbench.device import default_device
from gsbench.errors import InputError
from gsbench.priors import clipspace as C
from gsbench.priors.labels import label_view
from gsbench.priors.weights import require_weights
from gsbench.resize import resize_nearest

FEATURE_DIM = C.DIM
CANONICAL_NEGATIVES = C.CANONICAL_NEGATIVES
UNLABELLED = C.BACKGROUND

CONTEXT_GROW = 0.5


def _unit_rows(x: np.ndarray) -> np.ndarray:
    return C.unit(x).astype(np.float32)


normalise_name = C.normalise_name


def label_ids(labels: np.ndarray) -> list[int]:
    return [int(i) for i in np.unique(labels[labels >= 0])]


class FeatureProvider:
    """Base: `.id`, `.encode_text(texts) -> (Q, 512)` unit rows, `.encode_masks(...)`."""

    id: str = "?"
    dim: int = FEATURE_DIM
    needs_image: bool = False
    canonical_negatives: tuple[str, ...] = CANONICAL_NEGATIVES

    def encode_text(self, texts: Sequence[str]) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def encode_masks(self, scene, view: int, image: np.ndarray, labels: np.ndarray,
                     seed: int = 0) -> dict[int, np.ndarray]:  # pragma: no cover - abstract
        raise NotImplementedError

    def cache_params(self) -> dict:
        return {"id": self.id}


def _number(value, key: str, hi: float | None = None) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{key}: must be a number, got {value!r}") from None
    if not np.isfinite(v) or v < 0 or (hi is not None and v > hi):
        raise InputError(f"{key}: must be in [0, {hi if hi is not None else 'inf'}], got {v}")
    return v


def named_class_map(scene, view: int, size: tuple[int, int]) -> tuple[np.ndarray | None, list[str]]:
    """GT class per pixel of `view` at `size` = (W, H) (-1 none) and the names its indices refer to.

    From 3D-OVS class masks, else instance maps with instance classes (synthetic scenes), else LERF
    label polygons (categories). The map is None when the view has no labels: its masks get no
    feature, hence no semantic target."""
    if scene.has_semantics:
        c = scene.gt_classes(view)
        return (None if c is None else resize_nearest(np.asarray(c).astype(np.int64), *size)), list(scene.class_names)
    if scene.has_instances and scene.instance_classes and scene.class_names:
        inst = resize_nearest(np.asarray(scene.gt_instances(view)).astype(np.int64), *size)
        lut = {int(k): int(c) for k, c in scene.instance_classes.items()}
        keys = np.array(sorted(lut), dtype=np.int64)
        vals = np.array([lut[k] for k in keys], dtype=np.int64)
        out = np.full(inst.shape, -1, np.int64)
        pos = np.isin(inst, keys)
        out[pos] = vals[np.searchsorted(keys, inst[pos])]
        return out, list(scene.class_names)
    if scene.has_labels:
        lv = label_view(scene, view, size)
        return (None, list(scene.queries)) if lv is None else (lv.classes.astype(np.int64), lv.names)
    raise InputError(f"{scene.path}: priors.features.provider=text-aligned needs GT classes (3D-OVS class "
                     "masks, LERF-OVS labels or a synthetic scene's instances); use openclip otherwise")


def gt_class_map(scene, view: int, size: tuple[int, int]) -> np.ndarray | None:
    """GT class index per pixel of `view` at `size` = (W, H) (-1 none); None for a view without labels."""
    return named_class_map(scene, view, size)[0]


def class_shares(cls: np.ndarray, region: np.ndarray, names: Sequence[str]) -> dict[str, float]:
    """Share of each class name among the pixels of `region` (no class: the background name)."""
    c = cls[region]
    if c.size == 0:
        return {}
    c = np.where((c >= 0) & (c < len(names)), c, -1)
    vals, counts = np.unique(c, return_counts=True)
    tot = float(counts.sum())
    return {(names[int(v)] if v >= 0 else UNLABELLED): float(n) / tot for v, n in zip(vals, counts)}


def context_ring(mask: np.ndarray) -> np.ndarray:
    """The crop's surroundings: the mask's bounding box grown by CONTEXT_GROW of its size, minus the mask."""
    ys, xs = np.nonzero(mask)
    H, W = mask.shape
    gy = int(np.ceil(CONTEXT_GROW * (ys.max() - ys.min() + 1) / 2))
    gx = int(np.ceil(CONTEXT_GROW * (xs.max() - xs.min() + 1) / 2))
    box = np.zeros_like(mask)
    box[max(0, ys.min() - gy):min(H, ys.max() + 1 + gy), max(0, xs.min() - gx):min(W, xs.max() + 1 + gx)] = True
    return box & ~mask


class TextAlignedFeatures(FeatureProvider):
    """Weight-free CLIP-like mask and text features (see module doc)."""

    version = 2

    def __init__(self, noise: float = 0.4, context: float = 0.15):
        self.noise = _number(noise, "priors.features.noise")
        self.context = _number(context, "priors.features.context", 1.0)
        self.id = f"text-aligned-clipsim-v{self.version}"

    def cache_params(self) -> dict:
        return {"id": self.id, "noise": self.noise, "context": self.context, "space": C.SPACE_VERSION}

    def encode_text(self, texts: Sequence[str]) -> np.ndarray:
        if len(texts) == 0:
            return np.zeros((0, FEATURE_DIM), np.float32)
        return np.stack([C.text_vector(t) for t in texts])

    def mask_shares(self, scene, view: int, labels: np.ndarray) -> dict[int, dict[str, float]]:
        """Per mask id: {class name: weight} of the mask's pixels mixed with its context ring."""
        cls, names = named_class_map(scene, view, (labels.shape[1], labels.shape[0]))
        out: dict[int, dict[str, float]] = {}
        if cls is None:   # a view without labels: its masks cannot be named
            return out
        for i in label_ids(labels):
            m = labels == i
            inside = class_shares(cls, m, names)
            ring = class_shares(cls, context_ring(m), names) if self.context > 0 else {}
            a = self.context if ring else 0.0
            mix = {k: (1.0 - a) * w for k, w in inside.items()}
            for k, w in ring.items():
                mix[k] = mix.get(k, 0.0) + a * w
            out[i] = mix
        return out

    def encode_masks(self, scene, view: int, image: np.ndarray, labels: np.ndarray,
                     seed: int = 0) -> dict[int, np.ndarray]:
        out = {}
        for i, mix in self.mask_shares(scene, view, labels).items():
            # seeded by what the mask covers, not its id: the same crop gives the same vector
            digest = hashlib.sha256(np.packbits(labels == i).tobytes()).hexdigest()[:16]
            n = C.random_direction("mask-noise", seed, view, digest)
            out[i] = C.image_vector(mix, self.noise, n)
        return out


def masked_square_crop(image: np.ndarray, mask: np.ndarray) -> np.ndarray | None:
    """Background blacked out, cropped to the mask's bbox, padded (black) to a square; None if empty."""
    m = np.asarray(mask, dtype=bool)
    if not m.any():
        return None
    ys, xs = np.nonzero(m)
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    img = np.asarray(image, dtype=np.float32)[..., :3] * m[..., None]
    crop = img[y0:y1, x0:x1]
    h, w = crop.shape[:2]
    s = max(h, w)
    out = np.zeros((s, s, 3), np.float32)
    oy, ox = (s - h) // 2, (s - w) // 2
    out[oy:oy + h, ox:ox + w] = crop
    return out


class OpenClipFeatures(FeatureProvider):
    """OpenCLIP (default ViT-B-16) from a local checkpoint file."""

    version = 1
    needs_image = True

    def __init__(self, checkpoint: str | None, model: str = "ViT-B-16", batch_size: int = 32,
                 device: str | None = None):
        require_weights("priors.features.checkpoint", checkpoint, "OpenCLIP ViT-B/16",
                        "priors.features.provider=openclip")
        try:
            import open_clip
        except ImportError as e:
            raise InputError(f"priors.features.provider=openclip needs the `models` extra "
                             f"(pip install -e .[models]): {e}") from None
        self.device = device or default_device()
        try:
            self.model, _, self.preprocess = open_clip.create_model_and_transforms(
                model, pretrained=str(checkpoint), device=self.device)
        except Exception as e:  # state-dict mismatch, corrupt file...
            raise InputError(f"priors.features.checkpoint: {checkpoint} does not load as OpenCLIP {model}: "
                             f"{type(e).__name__}: {e}") from None
        self.model = self.model.float().eval()
        self.tokenizer = open_clip.get_tokenizer(model)
        self.batch_size = int(batch_size)
        self.model_name = model
        self.id = f"openclip:{model}:{Path(checkpoint).name}"

    def cache_params(self) -> dict:
        return {"id": self.id, "model": self.model_name}

    def _check(self, f: np.ndarray, what: str) -> np.ndarray:
        if f.shape[-1] != FEATURE_DIM:
            raise InputError(f"priors.features: {self.id} gives {f.shape[-1]}-d {what} features, "
                             f"expected {FEATURE_DIM}")
        return _unit_rows(f)

    def encode_text(self, texts: Sequence[str]) -> np.ndarray:
        import torch
        if len(texts) == 0:
            return np.zeros((0, FEATURE_DIM), np.float32)
        with torch.inference_mode():
            tok = self.tokenizer(list(texts)).to(self.device)
            f = self.model.encode_text(tok).float().cpu().numpy()
        return self._check(f, "text")

    def encode_masks(self, scene, view: int, image: np.ndarray, labels: np.ndarray,
                     seed: int = 0) -> dict[int, np.ndarray]:
        import torch
        from PIL import Image
        ids, crops = [], []
        for i in label_ids(labels):
            c = masked_square_crop(image, labels == i)
            if c is None:
                continue
            u8 = np.clip(np.rint(c * 255), 0, 255).astype(np.uint8)
            crops.append(self.preprocess(Image.fromarray(u8)))
            ids.append(i)
        out: dict[int, np.ndarray] = {}
        for k in range(0, len(crops), self.batch_size):
            batch = torch.stack(crops[k:k + self.batch_size]).to(self.device)
            with torch.inference_mode():
                f = self.model.encode_image(batch).float().cpu().numpy()
            for i, row in zip(ids[k:k + self.batch_size], self._check(f, "image")):
                out[i] = row
        return out


_PROVIDERS: dict[tuple, FeatureProvider] = {}


def get_feature_provider(features_cfg: Mapping, device: str | None = None) -> FeatureProvider:
    """The feature provider of the `priors.features` config; a model is loaded once per process and
    device, on `device` (None = CUDA when available, else the CPU)."""
    name = features_cfg.get("provider", "text-aligned")
    if name == "text-aligned":
        return TextAlignedFeatures(features_cfg.get("noise", 0.4), features_cfg.get("context", 0.15))
    if name == "openclip":
        key = ("openclip", features_cfg.get("checkpoint"), features_cfg.get("model", "ViT-B-16"), device)
        if key not in _PROVIDERS:
            _PROVIDERS[key] = OpenClipFeatures(features_cfg.get("checkpoint"), features_cfg.get("model", "ViT-B-16"),
                                               device=device)
        return _PROVIDERS[key]
    raise InputError(f"priors.features.provider: unknown provider {name!r} "
                     f"(expected one of {', '.join(FEATURE_PROVIDERS)})")
