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


# ----------------------------------------------------------------------------- the default, and run ids
def test_auto_is_the_default_and_settles_to_the_concrete_provider_s_run_id():
    from gsbench.config import run_id
    cfg = load_config("gaussiands")
    assert cfg["priors"]["depth"]["provider"] == "auto"
    gt = load_config("gaussiands", None, ["priors.depth.provider=gt"])
    sfm = load_config("gaussiands", None, ["priors.depth.provider=sfm"])
    with_depth, points_only = make_sphere_scene(2, *SIZE), _points_only()
    # unsettled, the rule has its own id; settled, the id of what it chose on that scene
    assert run_id(cfg, "fp") != run_id(gt, "fp")
    settled = D.settle_depth_rule(cfg, with_depth)
    assert settled["priors"]["depth"]["provider"] == "auto"       # the config keeps the rule it was given
    assert settled["resolved"] == {"priors.depth.provider": "gt"}
    assert run_id(settled, "fp") == run_id(gt, "fp")
    assert run_id(D.settle_depth_rule(cfg, points_only), "fp") == run_id(sfm, "fp")
    none = D.settle_depth_rule(cfg, _neither())
    assert none["resolved"]["priors.depth.provider"] == "none"
    assert run_id(none, "fp") not in (run_id(gt, "fp"), run_id(sfm, "fp"))
    # an explicit provider is left alone
    assert D.settle_depth_rule(gt, points_only) is gt


def test_a_stored_settlement_that_is_not_a_provider_name_is_ignored_by_the_id():
    from gsbench.config import run_id
    cfg = load_config("gaussiands")
    bad = {**cfg, "resolved": {"priors.depth.provider": ["gt"]}}
    assert run_id(bad, "fp") == run_id(cfg, "fp")


def test_grid_planning_settles_auto_on_a_generated_scene_without_generating_it():
    from gsbench.config import run_id
    from gsbench.grids.grid_file import SceneSpec
    from gsbench.grids.planning import settle_on_spec
    cfg = load_config("gaussiands")
    gt = load_config("gaussiands", None, ["priors.depth.provider=gt"])
    assert run_id(settle_on_spec(cfg, SceneSpec(preset="tabletop-medium")), "fp") == run_id(gt, "fp")
    # a folder scene that is not here stays unsettled: no published cell can match it by accident
    missing = SceneSpec(path="/nonexistent/scan")
    assert settle_on_spec(cfg, missing) is cfg
