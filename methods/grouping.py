"""`grouping`: a Gaussian Grouping-style baseline (Ye et al., ECCV 2024), trained jointly from scratch.

Every Gaussian carries an identity encoding (`grouping.identity_dim`, 16 in the paper) that is rendered
like colour (alpha-blended) and classified per pixel by one linear layer into `grouping.num_classes`
mask ids (256 in the paper; null = one per track plus the no-mask class). The targets are the
propagated pseudo-video masks of gsbench's priors (the masks GaussianDS gets, ids consistent across
views): track t is class t' >= 1 in sorted track order, pixels outside every mask are class 0 (the
paper's unassigned id). Losses per step:

    L = L_rec + lambda_id * CE(classifier(I_hat), ids) / log(C)
        + [every `reg3d.interval` steps] lambda_3d * mean_{s, j in kNN(s)} KL(p_s || p_j) / C

with p = softmax(classifier(identity)) per Gaussian, kNN by position (k = 5, the point itself included
as in the paper's code) among at most `reg3d.max_points` Gaussians, for `reg3d.sample_size` sampled ones.

Open-vocabulary queries go through the tracks' features: a track's feature is the renormalised mean of
its per-view mask features (the priors' CLIP-like vectors). A pixel's semantic feature is the feature of
the track its rendered identity classifies into (zero for class 0 and for ids no track owns), so the
cosine evaluation scores compare the query with the track the pixel belongs to: a query selects the
tracks whose feature best matches it, and its mask is where the identity classifies into them. Both
query modes give the same space (there is no autoencoder). Removal drops the Gaussians whose class
probability for the best-matching track exceeds `grouping.removal_threshold` (0.3 in the paper).
"""
from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Optional

import numpy as np
import torch

from gsbench.config import setting
from gsbench.errors import InputError
from gsbench.gaussians import SH_C0
from gsbench.methods.base import Method, Phases, _check_mode, fit_priors
from gsbench.methods.grouping_spec import budget
from gsbench.methods.registry import uses
from gsbench.train.adam import Adam
from gsbench.train.feature_blocks import FeatureBlocks
from gsbench.train.initial_field import scene_init
from gsbench.train.losses import reconstruction_loss
from gsbench.train.residency import data_on, place
from gsbench.train.trainer import LossFn, LossResult, StepContext, make_trainer
from gsbench.train.views import load_views

log = logging.getLogger(__name__)
NO_MASK = 0          # class of pixels outside every mask


# ---------------------------------------------------------------------------- losses (pure functions)
def identity_loss(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Cross-entropy of (P, C) logits against (P,) class ids, averaged over pixels and divided by log C
    (the paper's normalisation to about [0, 1])."""
    c = int(logits.shape[-1])
    if c < 2:
        raise ValueError(f"identity_loss needs at least 2 classes, got {c}")
    ce = torch.nn.functional.cross_entropy(logits, target, reduction="mean")
    return ce / math.log(c)


def neighbour_kl(means: torch.Tensor, probs: torch.Tensor, k: int, samples: torch.Tensor) -> torch.Tensor:
    """The 3D regulariser: for each sampled Gaussian s (indices into `means`), the mean over its k nearest
    Gaussians j by position (s itself included, distance 0) of KL(p_s || p_j) = sum_c p_sc (log p_sc -
    log p_jc), with 1e-10 inside the logs; averaged over samples and divided by the class count C."""
    n, c = probs.shape
    k = max(1, min(int(k), n))
    d = torch.cdist(means[samples], means)                        # (S, N)
    nbr = d.topk(k, largest=False).indices                        # (S, k)
    ps = probs[samples].unsqueeze(1)                              # (S, 1, C)
    pn = probs[nbr]                                               # (S, k, C)
    kl = (ps * (torch.log(ps + 1e-10) - torch.log(pn + 1e-10))).sum(-1)
    return kl.mean() / c


def sample_reg3d(n: int, max_points: int, sample_size: int, gen: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """(pool, samples): a random subset of at most `max_points` Gaussians to search neighbours in, and
    `sample_size` of them (indices into the pool) to regularise."""
    dev = gen.device
    pool = torch.randperm(n, generator=gen, device=dev)[:max_points] if n > max_points else torch.arange(n, device=dev)
    samples = torch.randperm(len(pool), generator=gen, device=dev)[:sample_size]
    return pool, samples


# ---------------------------------------------------------------------------- targets and tracks
def track_classes(masks: dict[int, np.ndarray], num_classes: Optional[int]) -> tuple[list[int], int]:
    """(sorted track ids of the masks, class count): track j of the list is class j + 1; num_classes None =
    len(tracks) + 1. Too many tracks for the given count is an error."""
    ids = sorted({int(t) for m in masks.values() for t in np.unique(np.asarray(m)) if t >= 0})
    if num_classes is None:
        return ids, max(2, len(ids) + 1)
    if len(ids) + 1 > num_classes:
        raise InputError(f"grouping: the masks hold {len(ids)} tracks but grouping.num_classes={num_classes} "
                         f"(needs >= {len(ids) + 1}: one class per track plus the no-mask class; null = that many)")
    return ids, int(num_classes)


def class_map(mask: np.ndarray, tracks: list[int]) -> np.ndarray:
    """(H, W) track ids (-1 none) -> (H, W) int64 class ids (0 none, track j of `tracks` -> j + 1)."""
    m = np.asarray(mask, dtype=np.int64)
    out = np.zeros(m.shape, dtype=np.int64)
    for j, t in enumerate(tracks):
        out[m == t] = j + 1
    return out


def track_table(mask_features: dict, tracks: list[int], num_classes: int, dim: int) -> torch.Tensor:
    """(C, dim) feature per class: row j + 1 = the renormalised mean of track j's per-view features;
    row 0 (no mask) and rows no track owns are zero."""
    table = np.zeros((num_classes, dim), dtype=np.float64)
    for (_, t), f in mask_features.items():
        if int(t) in tracks:
            table[tracks.index(int(t)) + 1] += np.asarray(f, dtype=np.float64).reshape(-1)
    norms = np.linalg.norm(table, axis=1, keepdims=True)
    table = np.where(norms > 1e-12, table / np.maximum(norms, 1e-12), 0.0)   # opposite vectors may cancel
    return torch.as_tensor(table, dtype=torch.float32)


# ---------------------------------------------------------------------------- the method
class GaussianGrouping(Method):
    name = "grouping"

    def __init__(self) -> None:
        super().__init__()
        self.classifier: Optional[torch.nn.Linear] = None
        self.tracks: list[int] = []
        self.table: Optional[torch.Tensor] = None       # (C, 512) class -> track feature

    @property
    def has_semantics(self) -> bool:
        return (self.field is not None and self.field.features is not None and self.classifier is not None
                and self.table is not None)

    def classify(self, identity: torch.Tensor) -> torch.Tensor:
        """(..., d) identity encodings -> (...) class ids (argmax of the classifier)."""
        with torch.no_grad():
            return self.classifier(identity).argmax(-1)

    def semantic_feature_blocks(self, camera, modes: tuple) -> dict:
        """{mode: FeatureBlocks of (H, W, 512)}: the feature of the track each pixel's rendered identity
        classifies into, a block of pixels at a time, the same for both modes (no autoencoder), from
        one render."""
        for m in modes:
            _check_mode(m)
        if not self.has_semantics:
            return {m: None for m in modes}
        blocks = FeatureBlocks.of_map(self.render(camera).features, lambda ids: self.table[self.classify(ids)])
        return {m: blocks for m in modes}

    def gaussian_semantic_features(self, mode: str = "encode") -> Optional[torch.Tensor]:
        """(N, 512) the feature of the track each Gaussian's own identity encoding classifies into (both
        modes; zero for class 0 and for classes no track owns)."""
        _check_mode(mode)
        if not self.has_semantics:
            return None
        return self.table[self.classify(self.field.features)]

    def embed_text(self, texts: list[str], mode: str = "encode") -> Optional[torch.Tensor]:
        """(Q, 512) unit text embeddings of the feature provider (both modes: the tracks' feature space)."""
        return self._unit_provider_text(texts, mode)

    def query_classes(self, text: str) -> list[int]:
        """The classes (tracks) a text query selects: those whose track feature has the highest cosine."""
        q = self.embed_text([text])[0]
        cos = self.table @ q
        owned = self.table.norm(dim=-1) > 1e-12
        if not bool(owned.any()):
            return []
        best = cos[owned].max()
        return [int(c) for c in torch.nonzero(owned & (cos >= best)).flatten()]

    def remove(self, query: str, threshold: Optional[float] = None) -> tuple["Method", int]:
        """A copy without the Gaussians whose class probability for the query's track(s) exceeds
        grouping.removal_threshold (the paper's rule; `threshold`, GaussianDS's cosine, does not apply)."""
        if not self.has_semantics:
            raise ValueError(f"method {self.name}: object removal needs identity encodings (this run has none)")
        if threshold is not None:
            log.info("grouping: removal by class probability > grouping.removal_threshold; the latent-cosine "
                     "threshold %s does not apply", threshold)
        thr = float(setting(self.config, "grouping.removal_threshold"))
        sel = self.query_classes(query)
        fld = self._require_field()
        with torch.no_grad():
            prob = torch.softmax(self.classifier(fld.features), dim=-1)
        drop = (prob[:, sel] > thr).any(-1) if sel else torch.zeros(fld.num, dtype=torch.bool, device=self.device)
        out = self.with_field(fld.subset(~drop))
        out.info = dict(self.info, removed_query=query, removal_rule=f"class probability > {thr:g}",
                        removal_classes=sel)
        return out, int(drop.sum())

    # ------------------------------------------------------------------ persistence
    def state(self) -> dict:
        st = super().state()
        st["grouping"] = None if self.classifier is None else {
            "classifier": {k: v.cpu() for k, v in self.classifier.state_dict().items()},
            "tracks": list(self.tracks), "table": self.table.cpu()}
        return st

    def _restore(self, st: dict, device: torch.device) -> None:
        g = st.get("grouping")
        if not g:
            return
        w = g["classifier"]["weight"]
        self.classifier = torch.nn.Linear(w.shape[1], w.shape[0])
        self.classifier.load_state_dict(g["classifier"])
        self.classifier.to(device).eval()
        self.tracks = [int(t) for t in g["tracks"]]
        self.table = g["table"].to(device)

    # ------------------------------------------------------------------ training
    def train_phases(self, scene, run_dir: Path, config: dict, resume: Optional[dict] = None,
                     progress: bool = True) -> Phases:
        run_dir = Path(run_dir)
        dev = self._prepare(config)
        seed = int(setting(config, "seed"))
        semantic = bool(uses(config)["semantics"])
        views, (W, H) = load_views(scene, config, device=dev)
        train_ids = sorted(views.cameras)
        ckpt = resume
        dim = int(setting(config, "grouping.identity_dim")) if semantic else 0
        targets: Mapping[int, torch.Tensor] = {}
        has_any: dict[int, bool] = {}
        if semantic:
            targets, has_any = self._identity_targets(scene, config, run_dir, progress, train_ids, (W, H), dim, dev)

        field0, how = scene_init(scene, config, 0)
        self.info["init"] = how
        if semantic:   # the paper's init: uniform colours in [0, 1) turned into SH DC coefficients
            ident = (np.random.default_rng(seed + 2).random((field0.num, dim)) - 0.5) / SH_C0
            field0 = field0.with_features(torch.as_tensor(ident, dtype=torch.float32))
        opt = None
        gen = torch.Generator(device=dev).manual_seed(seed + 3)
        resumed = ckpt if (ckpt is not None and ckpt.get("phase") == "main") else None
        if semantic:
            opt = Adam(self.classifier.parameters(), lr=float(setting(config, "grouping.classifier_lr")))
            extra = (resumed or {}).get("extra", {})
            if "classifier" in extra:
                self.classifier.load_state_dict(extra["classifier"])
                opt.load_state_dict(extra["classifier_optimizer"])
                gen.set_state(extra["reg3d_generator"])

        loss_fn = self._loss_fn(config, semantic, dim, targets, has_any, gen)

        def extra_state() -> dict:
            if self.classifier is None:
                return {}
            return {"classifier": self.classifier.state_dict(), "classifier_optimizer": opt.state_dict(),
                    "reg3d_generator": gen.get_state()}

        self.field = yield make_trainer(config, views, scene, field0, run_dir, loss_fn, phase="main",
                                        backend=self._backend, extra_state=extra_state, extra_optimizer=opt)
        if self.classifier is not None:
            self.classifier.eval()
        self.info["n_gaussians"] = self.field.num
        self.info["device"] = str(dev)
        self.info["budget"] = budget(config)   # one joint phase: identity, classifier and RGB every step

    def _identity_targets(self, scene, config: dict, run_dir: Path, progress: bool, train_ids: list[int],
                          size: tuple[int, int], dim: int, dev) -> tuple[Mapping[int, torch.Tensor], dict[int, bool]]:
        """The priors' propagated masks as per-pixel class targets (tracks -> classes, the tracks' feature
        table, a seeded classifier), and per view whether it has any target at all."""
        W, H = size
        pri = fit_priors(scene, config, run_dir, progress=progress)
        self.providers = dict(pri.providers)
        self.info["priors_stats"] = dict(pri.stats)
        self.info["priors_skipped"] = dict(pri.skipped)
        if pri.masks is None or pri.mask_features is None:
            raise ValueError(f"grouping: the identity loss is on but the priors gave no masks/features "
                             f"({pri.skipped})")
        self.tracks, C = track_classes({v: pri.masks[v] for v in train_ids}, setting(config, "grouping.num_classes"))
        feat_dim = len(next(iter(pri.mask_features.values())))
        self.table = track_table(pri.mask_features, self.tracks, C, feat_dim).to(dev)
        targets: Mapping[int, torch.Tensor] = {}
        for v in train_ids:
            m = np.asarray(pri.masks[v])
            if m.shape != (H, W):
                raise ValueError(f"mask of view {v} has shape {m.shape}, expected {(H, W)} (training resolution)")
            targets[v] = torch.as_tensor(class_map(m, self.tracks)).reshape(-1)
        targets = place(targets, dev, data_on(config))
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(int(setting(config, "seed")))
            self.classifier = torch.nn.Linear(dim, C).to(dev)
        self.info["tracks"] = len(self.tracks)
        self.info["num_classes"] = C
        # views whose masks cover nothing (e.g. unlabelled views of gt masks) teach no identity
        has_any = {v: bool((np.asarray(pri.masks[v]) >= 0).any()) for v in train_ids}
        return targets, has_any

    def _loss_fn(self, config: dict, semantic: bool, dim: int, targets: Mapping[int, torch.Tensor],
                 has_any: dict[int, bool], gen: torch.Generator) -> LossFn:
        """The per-step loss (module docstring): L_rec, the identity loss on views with targets, and every
        `reg3d.interval` steps (the context's step) the 3D neighbour KL over sampled Gaussians (the
        context's parameters)."""
        # every setting read once here, not per step
        lam_dssim = float(setting(config, "train.lambda_dssim"))
        on_identity = setting(config, "grouping.losses.identity")
        on_reg3d = setting(config, "grouping.losses.reg3d")
        lam_identity = setting(config, "grouping.lambdas.identity")
        lam_reg3d = setting(config, "grouping.lambdas.reg3d")
        r3_interval = int(setting(config, "grouping.reg3d.interval"))
        r3_k = int(setting(config, "grouping.reg3d.k"))
        r3_max_points = int(setting(config, "grouping.reg3d.max_points"))
        r3_sample_size = int(setting(config, "grouping.reg3d.sample_size"))

        def loss_fn(ctx: StepContext) -> LossResult:
            vid, out = ctx.view_id, ctx.out
            rec = reconstruction_loss(out.rgb, ctx.gt, lam_dssim)
            res = LossResult(rec, {"rec": rec.detach()}, {}, {"rec": rec.detach()})
            if semantic and on_identity:
                if not has_any[vid]:
                    res.skipped["identity"] = 1
                else:
                    res.add("identity", lam_identity,
                            identity_loss(self.classifier(out.features.reshape(-1, dim)), targets[vid]))
            if semantic and on_reg3d and ctx.step % r3_interval == 0:
                p = ctx.params
                pool, samples = sample_reg3d(int(p["means"].shape[0]), r3_max_points, r3_sample_size, gen)
                probs = torch.softmax(self.classifier(p["features"][pool]), dim=-1)
                res.add("reg3d", lam_reg3d, neighbour_kl(p["means"].detach()[pool], probs, r3_k, samples))
            res.terms["total"] = res.total.detach()
            return res

        return loss_fn
