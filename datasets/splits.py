"""Which views a run trains on: the every-8th hold-out of the scene (or none), then the few-view pick.

`train.holdout` picks the held-out views: "every-8" keeps the scene's split (test views are held out
for the reconstruction metrics); "none" trains on every view, as the segmentation references do, and
leaves no view for PSNR / SSIM / LPIPS (the evaluation then skips them with a reason).

`train.views: N` is the few-view protocol of RegNeRF / FreeNeRF (and DNGaussian, FSGS, CoR-GS) on
LLFF: of the views the hold-out leaves, in the scene's view order, train on the N at positions
round(linspace(0, len - 1, N)), rounding halves to even as their loaders do (Python's `round` of
numpy's linspace). 20 views, every-8, N = 3: test 0, 8, 16; train 1, 10, 19. With `holdout: none`
the N are taken the same way over every view. null trains on every view the hold-out leaves.
Every reader orders a scene's views by image name (kaolin by view number), so the view order is
the name order (tests/datasets/test_few_view_split.py).
"""
from __future__ import annotations

import numpy as np

from gsbench.config import setting
from gsbench.config_keys import HOLDOUTS as HOLDOUT_CHOICES
from gsbench.errors import InputError

VIEWS_RULE = "round(linspace(0, n - 1, N)), halves to even, over the n views the hold-out leaves (RegNeRF)"


def split_ids(scene, config: dict) -> tuple[list[int], list[int]]:
    """(trained view ids, held-out view ids) of a run with this config."""
    holdout = setting(config, "train.holdout")
    if holdout not in HOLDOUT_CHOICES:
        raise InputError(f"train.holdout must be one of {', '.join(HOLDOUT_CHOICES)}, got {holdout!r}")
    if holdout == "none":
        pool, held = list(range(len(scene.cameras))), []
    else:
        pool, held = list(scene.train_ids), list(scene.test_ids)
    views = setting(config, "train.views")
    if views is None:
        return pool, held
    if isinstance(views, bool) or not isinstance(views, int) or views < 1:
        raise InputError(f"train.views must be null or an integer >= 1, got {views!r}")
    if views > len(pool):
        raise InputError(f"{scene.path}: train.views={views} but only {len(pool)} views are left to train on "
                         f"(train.holdout={holdout}, {len(scene.cameras)} views in the scene)")
    return spread(pool, views), held


def spread(pool: list[int], n: int) -> list[int]:
    """`n` of `pool` at positions round(linspace(0, len(pool) - 1, n)) (numpy rounds halves to even, as
    the references' Python `round` does); distinct because n <= len(pool) makes the step >= 1."""
    if not 1 <= n <= len(pool):
        raise ValueError(f"cannot take {n} of {len(pool)} views")
    positions = np.round(np.linspace(0, len(pool) - 1, n)).astype(int)
    return [pool[int(k)] for k in positions]


def split_record(scene, config: dict) -> dict:
    """The run's split as results.json keeps it: the settings, the trained and held-out view ids and
    their names (the image names of the views)."""
    trained, held = split_ids(scene, config)
    return {"holdout": setting(config, "train.holdout"), "views": setting(config, "train.views"),
            "trained_ids": trained, "trained_names": [_name(scene, i) for i in trained],
            "held_out_ids": held, "held_out_names": [_name(scene, i) for i in held]}


def _name(scene, i: int) -> str:
    return scene.cameras[i].name or str(i)
