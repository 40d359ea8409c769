"""Priors for semantic 3DGS: pseudo-video ordering, depth priors, view-consistent masks, mask features.

Public API (the priors interface in the team contract):
  prepare_priors(scene, priors_cfg, view_ids, image_size, cache_dir, need_depth, need_masks,
                 need_features, per_frame_masks=False, seed=0, progress=True) -> Priors
  get_feature_provider(features_cfg) -> FeatureProvider
  DepthPrior, Priors, FeatureProvider, CANONICAL_NEGATIVES

Modules: ordering (pose / random / filename chains), depth (gt / sparse / sfm / depth-anything),
sfm_depth (the weight-free sfm prior: SfM points densified along the photo's edges),
masks (gt / simulated / sam2), segmenter (SAM-like weight-free failures), propagation (carried
tracks, flow / reproject warps), clipspace (CLIP-geometry text/image space),
features (text-aligned / openclip), cache (content-hash disk cache), warp (geometry helpers),
pipeline (prepare_priors). Real providers import torch-vision libraries lazily.
"""
from gsbench.priors.depth import DepthPrior
from gsbench.priors.features import CANONICAL_NEGATIVES, FeatureProvider, get_feature_provider
from gsbench.priors.pipeline import Priors, prepare_priors

__all__ = ["DepthPrior", "Priors", "FeatureProvider", "CANONICAL_NEGATIVES", "get_feature_provider",
           "prepare_priors"]
