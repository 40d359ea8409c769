"""Compatibility names for code not yet moved to gsbench.evaluation (grids imports these three);
remove once every import reads gsbench.evaluation / gsbench.runs."""
from __future__ import annotations

from gsbench.evaluation import evaluate_run, resolve_protocols, score_mask_folder, segmentation_metrics
from gsbench.runs import env_info as machine_info

__all__ = ["evaluate_run", "resolve_protocols", "score_mask_folder", "segmentation_metrics", "machine_info"]
