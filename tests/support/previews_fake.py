"""Hand-made run previews (no training) for the previews and HTML report tests."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from gsbench.preview_files import write_previews

MAGENTA = (255, 0, 255)


def fake_previews(run_dir: Path, method: str, render_rgb: tuple = MAGENTA, semantic: bool = True) -> None:
    """Hand-made previews of one 3D-OVS frame (16 x 12, two classes) and one removal view."""
    h, w = 12, 16
    render = np.zeros((h, w, 3), np.uint8) + np.array(render_rgb, np.uint8)
    gt = np.full((h, w, 3), 128, np.uint8)
    depth = np.tile(np.linspace(1.0, 3.0, w, dtype=np.float16), (h, 1))
    left = np.zeros((h, w), np.uint8)
    left[:, :8] = 1
    queries = [{"query": "chair", "iou": 0.5, "biou": 0.25, "localized": None, "reason": None},
               {"query": "table", "iou": 1.0, "biou": 1.0, "localized": None, "reason": None}] if semantic else []
    masks = np.stack([left, 1 - left]) if semantic else np.zeros((0, h, w), np.uint8)
    frame = {"key": "3dovs_frame_00001", "file": "3dovs_frame_00001.npz", "protocol": "3dovs",
             "view": "frame_00001.png", "frame_set": "held-out", "scored_size": [w, h], "size": [w, h],
             "psnr": 21.5, "psnr_impl": "psnr/uint8-round/v1", "depth_range": [1.0, 3.0],
             "semantic_reason": None if semantic else f"method {method} has no semantic field",
             "metric_impl": {}, "queries": queries}
    arrays = {"3dovs_frame_00001": {"render": render, "gt": gt, "depth": depth, "alpha": np.full((h, w), 255, np.uint8),
                                    "gt_depth": depth, "pred": masks, "gt_masks": masks}}
    removal = []
    if semantic:
        removal = [{"key": "removal_frame_00001", "file": "removal_frame_00001.npz", "view": "frame_00001.png",
                    "query": "chair", "n_pruned": 7, "threshold": 0.9, "residual": 0.125, "psnr_outside": 30.0,
                    "impl": "removal/x", "size": [w, h], "scored_size": [w, h]}]
        arrays["removal_frame_00001"] = {"before": render, "after": gt, "gt_after": gt, "object": left}
    write_previews(run_dir, {"run_id": f"id-{run_dir.name}", "method": method, "scene": "bench",
                             "providers": {"features": "text-aligned"}, "backend": "torch", "query_mode": "encode",
                             "max_width": 320, "frames": [frame], "removal": removal,
                             "removal_reason": None if semantic else "no semantic field", "notes": {}},
                   arrays)
