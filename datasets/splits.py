"""Which views a run trains on: the every-8th hold-out of the scene, or every view.

`train.holdout` picks it: "every-8" keeps the scene's split (test views are held out for the
reconstruction metrics); "none" trains on every view, as the segmentation references do, and
leaves no view for PSNR / SSIM / LPIPS (the evaluation then skips them with a reason).
"""
from __future__ import annotations

from gsbench.config import setting
from gsbench.errors import InputError

HOLDOUT_CHOICES = ("every-8", "none")


def split_ids(scene, config: dict) -> tuple[list[int], list[int]]:
    """(trained view ids, held-out view ids) of a run with this config."""
    holdout = setting(config, "train.holdout")
    if holdout not in HOLDOUT_CHOICES:
        raise InputError(f"train.holdout must be one of {', '.join(HOLDOUT_CHOICES)}, got {holdout!r}")
    if holdout == "none":
        return list(range(len(scene.cameras))), []
    return list(scene.train_ids), list(scene.test_ids)
