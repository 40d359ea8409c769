"""gsbench.metrics: pure evaluation functions on numpy arrays / torch tensors.

Every number a result records names the implementation that produced it: the ids are in
`METRIC_IMPL` (metric name of gsbench.results -> id) and in each function's result. The protocols
are described in docs/protocols.md; the module docstrings state every rule (borders, empty masks, ties).
Bad input raises gsbench.errors.InputError. Images are (H, W) or (H, W, C) in [0, 1].

Image metrics (image.py, perceptual.py)
  psnr(pred, gt, *, quantize=True, mask=None) -> float         uint8-rounded by default; 100 dB cap;
                                                               mask: MSE over selected pixels only
  ssim(pred, gt, *, border="zeropad"|"valid") -> float      Gaussian 11 / 1.5, K1 .01, K2 .03;
                                                               zeropad = the 3DGS form (default)
  ssim_map(pred, gt, *, border="zeropad") -> (H', W', C) array
  lpips(pred, gt, *, net="vgg"|"alex", model=None, weights_dir=None, device="cpu") -> LPIPSResult
      LPIPSResult(value: float | None, reason: str | None, impl: str, net: str); value None
      with the reason when the weights are absent ($GSBENCH_WEIGHTS or the torch hub cache).
  load_lpips(net="vgg", weights_dir=None) -> (LPIPSNet | None, reason | None)
  build_lpips_network(net="vgg", *, random_init=True, seed=0) -> LPIPSNet   tests only
  find_lpips_weights(net, weights_dir=None) -> (backbone path | None, lin path | None, searched)

Masks (segmentation.py)
  iou(pred, gt, *, empty=1.0) -> float                          `empty` for an empty union
  boundary_width(H, W, dilation_ratio=0.02) -> int              d = max(1, round(ratio * diag))
  boundary_band(mask, *, dilation_ratio=0.02, width=None) -> bool (H, W)
  boundary_iou(pred, gt, *, dilation_ratio=0.02, empty=1.0, coco_min=False) -> float
  miou(values) -> float | None;  mbiou(values) -> float | None   plain means (None if no value)

LERF-OVS, the LangSplat protocol (lerf.py)
  lerf_relevancy(pixel_features (H,W,D), query (D,)|(Q,D), negatives (J,D), *, pixel_norms=None)
      -> (H,W)|(Q,H,W)
  pixel_norms(pixel_features (H,W,D), name) -> (H*W,) float64: computed once, passed to both
      protocols' functions scoring the same map
  pixel_text_cosines(pixel_features (H,W,D), texts (K,D), name, norms=None) -> ((H*W, K) float64, (H, W))
  lerf_texts(query, negatives) -> ((Q+J, D), Q, single);  relevancy_from_cosines(cos, Q, H, W) -> (Q,H,W)
      lerf_relevancy in two steps, for cosines computed a block of pixels at a time
  lerf_blend(r) -> r' = 0.5 (r + mean30x30(r));  box_mean(r, size=30)
  lerf_mask(r_blend, *, threshold=0.7, window="langsplat") -> bool (H, W)
  majority_smooth(mask, *, radius=3, window="langsplat"|"centered") -> bool (H, W)
  select_level(blended_maps) -> int;  lerf_localization(relevancy_levels, bboxes) -> bool
  evaluate_lerf_scene(pairs: [LerfPair(frame, query, relevancy, gt_mask, gt_bboxes)], *,
                      threshold=0.7, missing="error"|"skip"|"zero", window="langsplat")
      -> LerfSceneResult(miou, loc_acc, per_pair, skipped, n_pairs, n_iou, n_loc, missing, impl, params)
  CANONICAL_NEGATIVES = ("object", "things", "stuff", "texture")

3D-OVS (ovs3d.py)
  ovs3d_predict(pixel_features (H,W,D), class_embeddings (C,D), *, pixel_norms=None)
      -> int32 (H, W) argmax of cosine
  class_texts(class_embeddings) -> (C, D);  ovs3d_labels(cos (H*W, C), H, W) -> int32 (H, W)
      ovs3d_predict in two steps
  resize_nearest(mask, width, height) -> same dtype (height, width), centre sampling (PIL NEAREST)
  ovs3d_view_metrics(pred_labels, gt_masks {class: mask}, class_names, *, dilation_ratio=0.02) -> dict
  evaluate_ovs3d_scene(views: [Ovs3dView(name, pred_labels, gt_masks)], class_names, *,
                       missing="error"|"skip"|"zero", dilation_ratio=0.02)
      -> Ovs3dSceneResult(miou, mbiou, pixel_acc, per_view, skipped, n_views, missing, impl, params)

Pseudo-video ordering (ordering.py)
  mean_adjacent_distance(centers (N,3), order) -> float | None
  adjacent_mask_iou(masks_in_order, depths, cameras, *, occlusion_tol=0.05) -> float | None
      cameras: Camera objects or (K, world_to_camera) pairs; depth = camera-space z
  adjacent_mask_iou_pairs(...) -> [{"pair", "ious", "n_excluded", "covered_fraction"}]

Timing (timing.py)
  time_fps(fn, warmup=3, repeats=10, sync=None) -> {"median_ms", "fps", "times_ms", "warmup",
                                                    "repeats", "sync", "impl"}
"""
from __future__ import annotations

from gsbench.resize import NEAREST_IMPL, resize_nearest

from ._common import pixel_norms, pixel_text_cosines
from .image import PSNR_IMPL, SSIM_IMPL, psnr, quantize_uint8, ssim, ssim_map

from .lerf import (CANONICAL_NEGATIVES, LERF_IMPL, LerfPair, LerfSceneResult, box_mean,  # isort: skip
                   evaluate_lerf_scene, lerf_blend, lerf_localization, lerf_mask, lerf_relevancy, lerf_texts,
                   majority_smooth, relevancy_from_cosines, select_level)
from .ordering import (ORDERING_DISTANCE_IMPL, ORDERING_MASK_IOU_FLOW_IMPL, ORDERING_MASK_IOU_IMPL,  # isort: skip
                       ORDERING_MASK_IOU_STRICT_IMPL, adjacent_mask_iou, adjacent_mask_iou_flow,
                       adjacent_mask_iou_pairs, adjacent_mask_iou_strict, mean_adjacent_distance)
from .ovs3d import (OVS3D_IMPL, PIXEL_ACC_IMPL, PIXEL_ACC_RULES, Ovs3dSceneResult, Ovs3dView,  # isort: skip
                    class_texts, evaluate_ovs3d_scene, ovs3d_labels, ovs3d_predict, ovs3d_view_metrics,
                    pixel_accuracy)
from .perceptual import (LPIPS_RANGES, LPIPSNet, LPIPSResult, build_lpips_network, find_lpips_weights,  # isort: skip
                         load_lpips, lpips, lpips_impl)
from .segmentation import BIOU_IMPL, IOU_IMPL, boundary_band, boundary_iou, boundary_width, iou, mbiou, miou
from .timing import FPS_IMPL, time_fps

#: metric name (gsbench.results.METRIC_NAMES) -> implementation id of the default settings.
#: A caller that changes a setting (quantize=False, border="valid", net="alex", ...) records
#: the id of that setting: PSNR_IMPL[quantize], SSIM_IMPL[border], lpips_impl(net, input_range=...).
#: `ssim` and `lpips` are the 3DGS forms (what 3DGS-family papers report); `ssim_valid` and
#: `lpips_package` keep the other conventions.
METRIC_IMPL: dict[str, str] = {
    "psnr": PSNR_IMPL[True],
    "ssim": SSIM_IMPL["zeropad"],
    "ssim_valid": SSIM_IMPL["valid"],
    "lpips": lpips_impl("vgg", input_range="3dgs-[0,1]"),
    "lpips_package": lpips_impl("vgg", input_range="lpips-[-1,1]"),
    "fps": FPS_IMPL,
    "iou": IOU_IMPL,
    "boundary_iou": BIOU_IMPL,
    "miou_lerf": LERF_IMPL,
    "loc_acc_lerf": LERF_IMPL,
    "miou_lerf_encode": LERF_IMPL,
    "miou_lerf_decode": LERF_IMPL,
    "miou_3dovs": OVS3D_IMPL,
    "mbiou_3dovs": OVS3D_IMPL + "+" + BIOU_IMPL,
    "pixel_acc_3dovs": OVS3D_IMPL + "+" + PIXEL_ACC_IMPL["reference"],
    "pixel_acc_labelled_3dovs": OVS3D_IMPL + "+" + PIXEL_ACC_IMPL["labelled"],
    "miou_3dovs_encode": OVS3D_IMPL,
    "miou_3dovs_decode": OVS3D_IMPL,
    "mbiou_3dovs_encode": OVS3D_IMPL + "+" + BIOU_IMPL,
    "mbiou_3dovs_decode": OVS3D_IMPL + "+" + BIOU_IMPL,
    "ordering_adjacent_distance": ORDERING_DISTANCE_IMPL,
    "ordering_adjacent_mask_iou": ORDERING_MASK_IOU_IMPL,
    "ordering_adjacent_mask_iou_strict": ORDERING_MASK_IOU_STRICT_IMPL,
    "ordering_adjacent_mask_iou_flow": ORDERING_MASK_IOU_FLOW_IMPL,
}

__all__ = [
    "METRIC_IMPL", "psnr", "ssim", "ssim_map", "quantize_uint8", "lpips", "load_lpips", "build_lpips_network",
    "find_lpips_weights", "lpips_impl", "LPIPSNet", "LPIPSResult", "iou", "boundary_band", "boundary_width",
    "boundary_iou", "miou", "mbiou", "lerf_relevancy", "lerf_blend", "box_mean", "lerf_mask", "majority_smooth",
    "select_level", "lerf_localization", "evaluate_lerf_scene", "LerfPair", "LerfSceneResult",
    "CANONICAL_NEGATIVES", "ovs3d_predict", "pixel_norms", "pixel_text_cosines", "lerf_texts",
    "relevancy_from_cosines", "class_texts", "ovs3d_labels", "resize_nearest", "ovs3d_view_metrics",
    "evaluate_ovs3d_scene",
    "Ovs3dView", "Ovs3dSceneResult", "mean_adjacent_distance", "adjacent_mask_iou", "adjacent_mask_iou_pairs",
    "time_fps", "PSNR_IMPL", "SSIM_IMPL", "LERF_IMPL", "OVS3D_IMPL", "BIOU_IMPL", "IOU_IMPL", "FPS_IMPL",
    "ORDERING_DISTANCE_IMPL", "ORDERING_MASK_IOU_IMPL", "ORDERING_MASK_IOU_STRICT_IMPL", "ORDERING_MASK_IOU_FLOW_IMPL",
    "adjacent_mask_iou_strict", "adjacent_mask_iou_flow", "NEAREST_IMPL", "PIXEL_ACC_IMPL", "PIXEL_ACC_RULES",
    "pixel_accuracy", "LPIPS_RANGES",
]
