"""The Method protocol (NerfBaselines-like: train phases / render / save / load) and the shared
implementation.

Every method in gsbench is a Gaussian field plus, for semantic methods, a frozen feature autoencoder
and the id of the feature provider that embeds text. The harness owns the training loop
(gsbench/runs/training.py); a method prepares its data and yields its optimisation phases:

    m = get_method(config["method"])()
    gsbench.runs.training.train_method(m, scene, run_dir, config)   # runs m.train_phases(...), writes the log
                                                                # and checkpoints into run_dir
    m.save(run_dir / "model.pt"); m = Method.load(run_dir / "model.pt")
    m.render(camera)                          # RenderOutput; .features = rendered latent S_hat (or None)
    m.semantic_features(camera, "encode")     # (H, W, d) S_hat           | "decode": (H, W, 512) decoded
    m.embed_text(["mug"], "encode")           # (Q, d) AE-encoded text     | "decode": (Q, 512) CLIP text
    m.remove("mug", threshold)                # (copy without the Gaussians whose latent cosine > threshold, n_pruned)
    m.with_field(field)                       # m with another field (the loop's mid-phase evaluation)

`semantic_features` and `embed_text` return the same space per mode, so a consumer takes the cosine of
the two. Methods without semantics return None from both.
"""
from __future__ import annotations

import copy
import logging
from pathlib import Path
from typing import Generator, Optional

import numpy as np
import torch

from gsbench import rundir
from gsbench.camera import Camera
from gsbench.config import setting
from gsbench.config_keys import QUERY_MODES
from gsbench.device import resolve_device
from gsbench.errors import InputError
from gsbench.gaussians import GaussianField
from gsbench.methods.registry import build_priors_request, get_method
from gsbench.priors import get_feature_provider, prepare_priors
from gsbench.render import RenderOutput, render, resolve_backend
from gsbench.store import load_torch, save_torch_atomic
from gsbench.train.autoencoder import FeatureAutoencoder
from gsbench.train.feature_blocks import BLOCK_ROWS, FeatureBlocks
from gsbench.train.render_backend import prepare_backend, resolve_render_backend
from gsbench.train.trainer import Trainer

# what train_phases returns: yields each phase's Trainer, receives that phase's final field
Phases = Generator[Trainer, GaussianField, None]


def _unit(x: torch.Tensor) -> torch.Tensor:
    return x / x.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def removal_mask(latents: torch.Tensor, query: torch.Tensor, threshold: float) -> torch.Tensor:
    """True for Gaussians whose latent cosine with the (d,) query exceeds `threshold` (strictly)."""
    cos = (_unit(latents) * _unit(query.reshape(1, -1))).sum(-1)
    zero = latents.norm(dim=-1) <= 1e-12           # an all-zero latent has no direction: never removed
    return (cos > float(threshold)) & ~zero


class Method:
    """Shared implementation; subclasses implement `train_phases` (the harness runs the phases)."""

    name = "base"

    def __init__(self) -> None:
        self.field: Optional[GaussianField] = None
        self.config: dict = {}
        self.autoencoder: Optional[FeatureAutoencoder] = None
        self.providers: dict = {"depth": None, "masks": None, "features": None, "ordering": None}
        self._backend: str = "torch"
        self._feature_provider = None
        self._background_cache: dict = {}
        self.info: dict = {}

    # ------------------------------------------------------------------ protocol
    def train_phases(self, scene, run_dir: Path, config: dict, resume: Optional[dict] = None,
                     progress: bool = True) -> "Phases":  # pragma: no cover
        """Prepare (device, views, priors, initial field) and yield one optimisation phase at a time (a
        `Trainer`: the shared 3DGS recipe with this method's loss); the harness runs each phase's steps
        (`Trainer.train_iteration`) and sends its final field back. `resume` is the run's checkpoint
        (or None): what the method restores itself from it (e.g. its autoencoder); the harness restores
        the phase named in it. Set `self.field` (and `self.info`) before returning."""
        raise NotImplementedError

    def _prepare(self, config: dict) -> torch.device:
        """Keep the config and resolve the training device and render backend, before any work (so a
        bad device or backend fails at once, not mid-run)."""
        self.config = config
        dev = resolve_device(config)
        self._backend = resolve_render_backend(config, dev)
        prepare_backend(self._backend)
        return dev

    @property
    def backend(self) -> str:
        return self._backend

    @property
    def device(self) -> torch.device:
        """Where the field lives; evaluation renders (and synchronises timings) on this device."""
        return self._require_field().means.device

    def provider_ids(self) -> dict:
        return dict(self.providers)

    def _require_field(self) -> GaussianField:
        if self.field is None:
            raise RuntimeError(f"{self.name}: not trained or loaded")
        return self.field

    def _background(self) -> torch.Tensor:
        """train.background on the field's device, made once per device and value (not per render:
        on CUDA that would be a host-to-device copy inside the FPS timing)."""
        bg = setting(self.config, "train.background") or [0.0, 0.0, 0.0]
        key = (tuple(float(x) for x in bg), self.device)
        if key not in self._background_cache:
            self._background_cache[key] = torch.tensor(bg, dtype=torch.float32, device=self.device)
        return self._background_cache[key]

    def render(self, camera: Camera) -> RenderOutput:
        """RGB, depth, alpha and the rendered latent S_hat (features, or None) of a camera."""
        with torch.no_grad():
            return render(self._require_field(), camera, backend=self._backend, background=self._background())

    @property
    def has_semantics(self) -> bool:
        return self.field is not None and self.field.features is not None and self.autoencoder is not None

    def semantic_features(self, camera: Camera, mode: str = "encode") -> Optional[torch.Tensor]:
        """encode: rendered S_hat (H, W, d); decode: AE-decoded S_hat (H, W, 512), unit vectors."""
        _check_mode(mode)
        if not self.has_semantics:
            return None
        return self.semantic_features_modes(camera, (mode,))[mode]

    def semantic_features_modes(self, camera: Camera, modes: tuple) -> dict:
        """{mode: semantic_features(camera, mode)} from one render: `semantic_feature_blocks` put together."""
        return {m: None if b is None else b.join() for m, b in self.semantic_feature_blocks(camera, modes).items()}

    def semantic_feature_blocks(self, camera: Camera, modes: tuple) -> dict:
        """{mode: FeatureBlocks or None} from one render, what evaluation scores: the rendered latents
        (encode, one block) and their decoding, done a block of pixels at a time as the blocks are
        read (decode), so the whole 512-d map is never held."""
        for m in modes:
            _check_mode(m)
        if not self.has_semantics:
            return {m: None for m in modes}
        feats = self.render(camera).features
        return {m: FeatureBlocks.of_map(feats, None if m == "encode" else self._decode_rows) for m in modes}

    def gaussian_semantic_features(self, mode: str = "encode") -> Optional[torch.Tensor]:
        """(N, D) each Gaussian's own semantic feature in the space of `embed_text(texts, mode)`
        (encode: its latent; decode: the latent decoded to the text space, BLOCK_ROWS at a time), or
        None without semantics: what the 3D point-level protocol classifies (docs/protocols.md)."""
        _check_mode(mode)
        if not self.has_semantics:
            return None
        lat = self._require_field().features
        if mode == "encode" or lat.shape[0] == 0:
            return lat
        return torch.cat([self._decode_rows(lat[k:k + BLOCK_ROWS]) for k in range(0, lat.shape[0], BLOCK_ROWS)])

    def _decode_rows(self, rows: torch.Tensor) -> torch.Tensor:
        """(n, d) latents -> (n, 512) decoded unit features."""
        with torch.no_grad():
            return self.autoencoder.decode(rows)

    def feature_provider(self):
        if self._feature_provider is None:
            dev = self.field.means.device if self.field is not None else resolve_device(self.config)
            self._feature_provider = get_feature_provider(setting(self.config, "priors.features"), device=str(dev))
        return self._feature_provider

    def embed_text(self, texts: list[str], mode: str = "encode") -> Optional[torch.Tensor]:
        """encode: AE encoder of the provider's text embedding (Q, d); decode: the text embedding (Q, 512)."""
        _check_mode(mode)
        if not self.has_semantics:
            return None
        t = self._provider_text(texts)
        if mode == "decode":
            return _unit(t)
        with torch.no_grad():
            return self.autoencoder.encode(t)

    def _provider_text(self, texts: list[str]) -> torch.Tensor:
        """(Q, 512) the feature provider's text embeddings, on the method's device."""
        return torch.as_tensor(np.asarray(self.feature_provider().encode_text(list(texts)), dtype=np.float32),
                               device=self.device)

    def _unit_provider_text(self, texts: list[str], mode: str) -> Optional[torch.Tensor]:
        """`embed_text` of a method without an autoencoder: (Q, 512) unit text embeddings of the feature
        provider, the same in both modes (None without semantics)."""
        _check_mode(mode)
        if not self.has_semantics:
            return None
        return _unit(self._provider_text(texts))

    def with_field(self, field: GaussianField) -> "Method":
        """This method with another field, everything else shared (config, autoencoder, providers, info):
        what the training loop's periodic evaluation scores mid-phase, and what removal returns. A subclass
        whose state depends on the field overrides it. The result shares this method's modules: read it,
        do not train it."""
        out = copy.copy(self)
        out.field = field
        return out

    def remove(self, query: str, threshold: Optional[float] = None) -> tuple["Method", int]:
        """Object removal: a copy without the Gaussians whose latent cosine with the encoded query > threshold."""
        if not self.has_semantics:
            raise ValueError(f"method {self.name}: object removal needs semantic latents (this run has none)")
        thr = float(setting(self.config, "removal.threshold") if threshold is None else threshold)
        q = self.embed_text([query], "encode")[0]
        fld = self._require_field()
        drop = removal_mask(fld.features, q, thr)
        out = self.with_field(fld.subset(~drop))
        out.info = dict(self.info, removed_query=query, removal_threshold=thr)
        return out, int(drop.sum())

    # ------------------------------------------------------------------ persistence
    def state(self) -> dict:
        return {"method": self.name, "field": self._require_field().state_dict(), "config": self.config,
                "autoencoder": None if self.autoencoder is None else
                {"config": self.autoencoder.config(), "state": self.autoencoder.state_dict()},
                "providers": self.providers, "backend": self._backend, "info": self.info}

    def save(self, path: str | Path) -> None:
        save_torch_atomic(Path(path), self.state())

    @classmethod
    def load(cls, path: str | Path, device: str | torch.device | None = None) -> "Method":
        """Load a saved model onto `device` (None = where its render backend runs: the CPU for the cpu
        backend, else CUDA when available, else the CPU); a saved render backend that cannot run there
        is re-resolved as `auto` for that device (logged)."""
        st = load_torch(Path(path))
        if not isinstance(st, dict) or "field" not in st:
            raise InputError(f"{path}: not a gsbench model file")
        dev = (torch.device(device) if device is not None
               else resolve_device({"train": {"device": "auto"}, "backend": st.get("backend", "torch")}))
        klass = get_method(st["method"]) if cls is Method else cls
        m = klass()
        m.field = GaussianField.from_state_dict(st["field"]).to(device=dev)
        m.config = st["config"]
        if st.get("autoencoder"):
            c = st["autoencoder"]["config"]
            ae = FeatureAutoencoder(c["in_dim"], c["latent_dim"], c["hidden"])
            ae.load_state_dict(st["autoencoder"]["state"])
            ae.eval()
            for p in ae.parameters():
                p.requires_grad_(False)
            m.autoencoder = ae.to(dev)
        m.providers = st.get("providers", m.providers)
        saved = st.get("backend", "torch")
        try:
            m._backend = resolve_backend(saved, dev)
        except InputError:
            m._backend = resolve_backend("auto", dev)
            logging.getLogger(__name__).info("%s: saved backend %s cannot render on %s; using %s",
                                             path, saved, dev, m._backend)
        prepare_backend(m._backend)
        m.info = st.get("info", {})
        m._restore(st, dev)
        return m

    def _restore(self, st: dict, device: torch.device) -> None:
        """Restore what a subclass added to `state()` (called by `load`); the base adds nothing."""


def _check_mode(mode: str) -> None:
    if mode not in QUERY_MODES:
        raise ValueError(f"query mode must be one of {', '.join(QUERY_MODES)}, got {mode!r}")


# ---------------------------------------------------------------------------- shared data preparation
def cache_dir_for(config: dict, run_dir: Path) -> Path:
    c = setting(config, "priors.cache_dir")
    return Path(c) if c else Path(run_dir).resolve().parent / rundir.CACHE_DIRNAME


def fit_priors(scene, config: dict, run_dir: Path, *, progress: bool):
    """The priors of a method's train_phases(): computed from the registry's priors request, the same dict a grid builds
    to share priors between cells, so the two cannot ask for different cache entries."""
    req = build_priors_request(config, scene)
    if req is None:
        raise InputError(f"{scene.path}: the scene has no training views")
    return prepare_priors(scene, req["priors"], req["view_ids"], tuple(req["size"]), cache_dir_for(config, run_dir),
                          need_depth=req["need_depth"], need_masks=req["need_sem"], need_features=req["need_sem"],
                          per_frame_masks=req["per_frame"], seed=req["seed"], progress=progress,
                          device=str(resolve_device(config)))
