"""Evaluation: a trained run -> results.json (`evaluate_run`), a folder of predicted masks ->
results.json (`score_mask_folder`). One job per module: frames (which views, at which size),
labels (ground truth), image (PSNR / SSIM / LPIPS / FPS), segmentation (every registered protocol),
removal, masks (prediction folders), run (the whole run). The protocols are a registry
(protocol_registry): one `*_protocol` file each (3D-OVS, LERF-OVS, 3D points) or an entry point."""
from __future__ import annotations

from .frames import FrameSets, frame_sets
from .labels import label_masks, read_label_file
from .masks import score_mask_folder
from .run import evaluate_run, segmentation_metrics
from .segmentation import PROTOCOLS, resolve_protocols

__all__ = ["evaluate_run", "score_mask_folder", "segmentation_metrics", "resolve_protocols", "PROTOCOLS",
           "frame_sets", "FrameSets", "label_masks", "read_label_file"]
