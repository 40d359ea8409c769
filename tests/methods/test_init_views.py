"""Initialisation sees only the views a run trains on: with `train.views`, the frustum init of a
forward-facing scene spreads its points over the N picked cameras, not over the scene's whole
training split (a few-view run must not start from geometry its views never saw)."""
from __future__ import annotations

import numpy as np
import pytest

from gsbench.config import load_config
from gsbench.datasets import load_scene
from gsbench.datasets.synthetic import make_scene
from gsbench.train.initial_field import frustum_points, scene_init


def test_frustum_init_uses_the_few_view_pick(tmp_path):
    root = make_scene("tabletop-small", tmp_path / "s", seed=0, views=10, resolution=(32, 24))
    if not (root / "poses_bounds.npy").is_file():
        pytest.skip("the generator wrote no poses_bounds.npy for this preset")
    sc = load_scene(root, layout="llff")
    cfg = load_config("vanilla", "cpu-small", ["train.init.num_random=300", "train.views=2"])
    fld, how = scene_init(sc, cfg, 0)
    assert how.startswith("frustum")
    # 10 views, every 8th held out: test 0 and 8, pool 1..7, 9; two at positions 0 and 7 -> views 1 and 9
    picked = [sc.cameras[1], sc.cameras[9]]
    want = frustum_points(picked, float(sc.meta["near"]), float(sc.meta["far"]), 300, int(cfg["seed"]))
    np.testing.assert_allclose(fld.means.numpy(), want, rtol=0, atol=1e-5)
    spread = frustum_points([sc.cameras[i] for i in sc.train_ids], float(sc.meta["near"]), float(sc.meta["far"]),
                            300, int(cfg["seed"]))
    assert not np.allclose(fld.means.numpy(), spread, atol=1e-3)   # the whole split would give other points
