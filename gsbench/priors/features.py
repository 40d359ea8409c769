"""Feature providers: 512-d unit vectors per mask and per text query (one shared space).

- ``text-aligned`` (weight-free simulation for synthetic scenes): every name gets a fixed unit
  vector drawn from a generator seeded by sha256 of the normalised name (lower case, single
  spaces), so it is stateless and identical at evaluation time. A mask's vector is the vector of
  the majority GT class under the mask in that view (pixels with no class vote for the reserved
  name ``UNLABELLED``), plus Gaussian noise whose expected L2 norm is ``noise`` (per-component
  std noise / sqrt(512), seeded by (seed, view, mask id)), renormalised. Text queries map to
  the same vectors; the canonical negatives get their own.
- ``openclip``: OpenCLIP ViT-B/16 from a local checkpoint, never downloading. A mask's crop:
  background blacked out, cropped to the mask's bounding box, padded to a square with black,
  then the model's own preprocessing (resize to 224 x 224, CLIP normalisation). L2-normalised.
"""
from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from gsbench.errors import InputError
from gsbench.priors.weights import require_weights

FEATURE_DIM = 512
CANONICAL_NEGATIVES = ("object", "things", "stuff", "texture")
UNLABELLED = "<unlabelled>"
FEATURE_PROVIDERS = ("text-aligned", "openclip")


def _unit_rows(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    n = np.linalg.norm(x, axis=-1, keepdims=True)
    if np.any(n <= 1e-12):
        raise ValueError("cannot normalise a zero feature vector")
    return (x / n).astype(np.float32)


def normalise_name(name: str) -> str:
    return " ".join(str(name).strip().lower().split())


def _seed_of(*parts) -> int:
    h = hashlib.sha256(":".join(str(p) for p in parts).encode("utf-8")).digest()
    return int.from_bytes(h[:8], "little")


def name_vector(name: str) -> np.ndarray:
    """The text-aligned table's fixed unit vector for `name` (stateless, deterministic)."""
    rng = np.random.default_rng(_seed_of("gsbench-text-aligned-v1", normalise_name(name)))
    return _unit_rows(rng.standard_normal(FEATURE_DIM))


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


class TextAlignedFeatures(FeatureProvider):
    """Weight-free text-aligned class table (see module doc)."""

    version = 1

    def __init__(self, noise: float = 0.05):
        noise = float(noise)
        if not np.isfinite(noise) or noise < 0:
            raise InputError(f"priors.features.noise: must be a finite number >= 0, got {noise}")
        self.noise = noise
        self.id = f"text-aligned-sim-v{self.version}"

    def cache_params(self) -> dict:
        return {"id": self.id, "noise": self.noise}

    def encode_text(self, texts: Sequence[str]) -> np.ndarray:
        if len(texts) == 0:
            return np.zeros((0, FEATURE_DIM), np.float32)
        return np.stack([name_vector(t) for t in texts])

    def mask_classes(self, scene, view: int, labels: np.ndarray) -> dict[int, str]:
        """Majority GT class name under each mask of `labels` in `view`."""
        from gsbench.priors.warp import resize_nearest
        size = (labels.shape[1], labels.shape[0])
        if scene.has_semantics:
            cls = resize_nearest(np.asarray(scene.gt_classes(view)).astype(np.int64), size)
        elif scene.has_instances and scene.instance_classes and scene.class_names:
            inst = resize_nearest(np.asarray(scene.gt_instances(view)).astype(np.int64), size)
            lut = {int(k): int(c) for k, c in scene.instance_classes.items()}
            cls = np.vectorize(lambda i: lut.get(int(i), -1), otypes=[np.int64])(inst) if inst.size else inst
        else:
            raise InputError(f"{scene.path}: priors.features.provider=text-aligned needs GT classes "
                             "(a synthetic scene); use openclip for real scenes")
        names = list(scene.class_names)
        out = {}
        lab = labels.astype(np.int64)
        for i in label_ids(labels):
            c = cls[lab == i]
            c = np.where((c >= 0) & (c < len(names)), c, -1)
            vals, counts = np.unique(c, return_counts=True)
            best = int(vals[np.argmax(counts)])       # ties: lowest class index (np.unique sorts)
            out[i] = names[best] if best >= 0 else UNLABELLED
        return out

    def encode_masks(self, scene, view: int, image: np.ndarray, labels: np.ndarray,
                     seed: int = 0) -> dict[int, np.ndarray]:
        out = {}
        for i, name in self.mask_classes(scene, view, labels).items():
            base = name_vector(name).astype(np.float64)
            rng = np.random.default_rng(_seed_of("text-aligned-noise", seed, view, i))
            noise = rng.standard_normal(FEATURE_DIM) * (self.noise / np.sqrt(FEATURE_DIM))
            out[i] = _unit_rows(base + noise)
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

    def __init__(self, checkpoint: str | None, model: str = "ViT-B-16", batch_size: int = 32):
        require_weights("priors.features.checkpoint", checkpoint, "OpenCLIP ViT-B/16",
                        "priors.features.provider=openclip")
        try:
            import open_clip
            import torch
        except ImportError as e:
            raise InputError(f"priors.features.provider=openclip needs the `models` extra "
                             f"(pip install -e .[models]): {e}") from None
        self.device = "cuda" if torch.cuda.is_available() else "cpu"
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
            raise InputError(f"priors.features: {self.id} gives {f.shape[-1]}-d {what} features, expected {FEATURE_DIM}")
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


def get_feature_provider(features_cfg: Mapping) -> FeatureProvider:
    """The feature provider of the `priors.features` config (models are loaded once per process)."""
    name = features_cfg.get("provider", "text-aligned")
    if name == "text-aligned":
        return TextAlignedFeatures(features_cfg.get("noise", 0.05))
    if name == "openclip":
        key = ("openclip", features_cfg.get("checkpoint"), features_cfg.get("model", "ViT-B-16"))
        if key not in _PROVIDERS:
            _PROVIDERS[key] = OpenClipFeatures(features_cfg.get("checkpoint"), features_cfg.get("model", "ViT-B-16"))
        return _PROVIDERS[key]
    raise InputError(f"priors.features.provider: unknown provider {name!r} "
                     f"(expected one of {', '.join(FEATURE_PROVIDERS)})")
