"""`priors.depth.provider: auto`: GT depth where the scene has it (then exactly the `gt` prior: same
values, id and cache entry), else `sfm` from the sparse points, else a depth model from local weights,
else no prior, dropped with its reason; the recorded provider says `auto -> <id>`."""
from __future__ import annotations

import copy

import numpy as np
from sphere_scene import make_sphere_scene

from gsbench.config import load_config
from gsbench.methods.registry import resolve_for_scene
from gsbench.methods.rules import depth_source
from gsbench.priors import depth as D
from gsbench.priors import prepare_priors

SIZE = (32, 24)


def _priors(scene, provider: str, cache_dir=None):
    return prepare_priors(scene, {"depth": {"provider": provider}}, [0, 1], SIZE, cache_dir, True, False, False,
                          seed=0, progress=False)


def _points_only():
    scene = make_sphere_scene(2, *SIZE)
    scene.depth_loader = None
    return scene


def _neither():
    scene = _points_only()
    scene.points = None
    return scene


def test_auto_on_a_scene_with_gt_depth_is_the_gt_prior_itself(tmp_path):
    scene = make_sphere_scene(2, *SIZE)
    gt = _priors(scene, "gt", tmp_path)
    auto = _priors(scene, "auto", tmp_path)
    assert auto.cache["depth"]["hit"]                    # the same cache entry as gt's
    assert auto.providers["depth"] == "auto -> " + gt.providers["depth"]
    assert gt.providers["depth"].startswith("gt-sim-disparity")
    for v in (0, 1):
        np.testing.assert_array_equal(auto.depth[v].values, gt.depth[v].values)
        np.testing.assert_array_equal(auto.depth[v].valid, gt.depth[v].valid)


def test_auto_on_a_scene_with_only_points_is_sfm():
    scene = _points_only()
    assert depth_source({"priors": {"depth": {"provider": "gt"}}}, scene)[0] is False
    assert depth_source({"priors": {"depth": {"provider": "auto"}}}, scene) == (True, "")
    p = _priors(scene, "auto")
    assert p.providers["depth"].startswith("auto -> sfm-fgs-")
    assert p.depth[0].kind == "disparity" and p.depth[0].valid.any()


def test_auto_without_depth_or_points_takes_a_configured_model_else_drops_with_the_note():
    scene = _neither()
    assert D.auto_depth_provider({"model_path": "/models/depth-anything-small"}, scene)[0] == "depth-anything"
    prov, why = D.auto_depth_provider({"model_path": None}, scene)
    assert prov is None and "no GT depth and no sparse points" in why
    assert depth_source({"priors": {"depth": {"provider": "auto"}}}, scene) == (False, why)
    p = _priors(scene, "auto")
    assert p.depth is None and p.skipped["depth"] == why


def test_gaussiands_keeps_its_depth_terms_with_auto_on_points_and_drops_them_without():
    cfg = load_config("gaussiands", None, ["priors.depth.provider=auto"])
    _, dropped = resolve_for_scene(copy.deepcopy(cfg), _points_only())
    assert "gaussiands.losses.depth" not in dropped and "priors.depth" not in dropped
    _, dropped = resolve_for_scene(copy.deepcopy(cfg), _neither())
    assert "priors.depth.provider=auto" in dropped["gaussiands.losses.depth"]
    assert "gaussiands.losses.ds" in dropped
