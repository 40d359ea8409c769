"""Config loading, overrides, run ids and the per-scene resolver."""
import numpy as np
import pytest

from gsbench.config import load_config, parse_overrides, resolve_for_scene, run_id
from gsbench.datasets.base import Scene
from gsbench.errors import InputError
from gsbench.scene import Camera


def test_defaults_carry_the_paper_weights():
    c = load_config("gaussiands")
    assert c["gaussiands"]["lambdas"] == {"depth": 0.01, "tv": 1.5, "sem": 5.0, "ds": 1.0}
    assert c["gaussiands"]["latent_dim"] == 3 and c["train"]["iterations"] == 30000
    assert c["gaussiands"]["depth_formulation"] == "scale_shift" and c["method"] == "gaussiands"


def test_preset_then_overrides():
    c = load_config("vanilla", "cpu-small", ["train.iterations=77", "gaussiands.lambdas.tv=0.5", "train.max_width=null",
                                             "train.background=[1, 1, 1]", "gaussiands.losses.ds=false"])
    assert c["method"] == "vanilla"
    assert c["train"]["iterations"] == 77 and c["gaussiands"]["lambdas"]["tv"] == 0.5
    assert c["train"]["max_width"] is None and c["train"]["background"] == [1, 1, 1]
    assert c["gaussiands"]["losses"]["ds"] is False
    assert c["train"]["densify"]["enabled"] is True                  # untouched keys keep the default
    assert parse_overrides({"a": {"b": 1}}) == {"a.b": 1} == parse_overrides(["a.b=1"])


@pytest.mark.parametrize("bad", [["train.iteration=5"], ["nokey=1"], ["train.iterations"], ["gaussiands.depth_formulation=foo"],
                                 ["gaussiands.latent_dim=0"], ["query.mode=both"]])
def test_bad_overrides_are_input_errors(bad):
    with pytest.raises(InputError):
        load_config("gaussiands", None, bad)


def test_unknown_method_and_preset():
    with pytest.raises(InputError, match="unknown method"):
        load_config("nerf")
    with pytest.raises(InputError, match="unknown preset"):
        load_config("gaussiands", "no-such-preset")


def test_run_id_depends_on_config_and_scene_not_cache_dir():
    a = load_config("gaussiands", "cpu-small")
    b = load_config("gaussiands", "cpu-small", ["priors.cache_dir=/somewhere/else"])
    c = load_config("gaussiands", "cpu-small", ["seed=1"])
    assert run_id(a, "fp1") == run_id(b, "fp1")
    assert run_id(a, "fp1") != run_id(c, "fp1")
    assert run_id(a, "fp1") != run_id(a, "fp2")
    assert len(run_id(a, "fp1")) == 16


def _scene(depth=True, instances=True, points=True):
    cam = Camera(np.array([[10.0, 0, 4], [0, 10, 3], [0, 0, 1]]), np.eye(4), 8, 6)
    return Scene(name="t", path="/x", layout="test", cameras=[cam], train_ids=[0], test_ids=[], image_paths=["a.png"],
                 class_names=["a", "b"] if instances else [],
                 points=np.zeros((3, 3)) if points else None,
                 depth_loader=(lambda i: np.ones((6, 8), np.float32)) if depth else None,
                 instances_loader=(lambda i: np.zeros((6, 8), np.int32)) if instances else None,
                 classes_loader=(lambda i: np.zeros((6, 8), np.int32)) if instances else None,
                 instance_classes={0: 0} if instances else {})


def test_resolver_keeps_everything_on_a_full_scene():
    cfg, dropped = resolve_for_scene(load_config("gaussiands"), _scene())
    assert dropped == {} and cfg["dropped"] == {}
    assert all(cfg["gaussiands"]["losses"].values())


def test_resolver_drops_depth_terms_without_depth_prior():
    cfg, dropped = resolve_for_scene(load_config("gaussiands"), _scene(depth=False))
    on = cfg["gaussiands"]["losses"]
    assert on["depth"] is False and on["ds"] is False and on["tv"] is True and on["sem"] is True
    assert "GT depth" in dropped["gaussiands.losses.depth"] and "priors.depth" in dropped
    # the sparse provider works from points
    cfg2, d2 = resolve_for_scene(load_config("gaussiands", None, ["priors.depth.provider=sparse"]), _scene(depth=False))
    assert cfg2["gaussiands"]["losses"]["depth"] is True and d2 == {}


def test_resolver_drops_semantics_without_semantics():
    cfg, dropped = resolve_for_scene(load_config("gaussiands"), _scene(instances=False))
    on = cfg["gaussiands"]["losses"]
    assert on["sem"] is False and on["ds"] is False and on["depth"] is True
    for part in ("priors.masks", "priors.features", "gaussiands.autoencoder", "semantic_channels"):
        assert "no semantics in the scene" in dropped[part]


def test_resolver_vanilla_twostage_and_formulation_none():
    cfg, dropped = resolve_for_scene(load_config("vanilla"), _scene())
    assert not any(cfg["gaussiands"]["losses"].values()) and "priors.depth" in dropped
    cfg, dropped = resolve_for_scene(load_config("twostage"), _scene())
    on = cfg["gaussiands"]["losses"]
    assert on["sem"] and not (on["depth"] or on["tv"] or on["ds"])
    cfg, dropped = resolve_for_scene(load_config("gaussiands", None, ["gaussiands.depth_formulation=none"]), _scene())
    assert cfg["gaussiands"]["losses"]["depth"] is False and cfg["gaussiands"]["losses"]["ds"] is True
    assert "formulation=none" in dropped["gaussiands.losses.depth"]
    cfg, dropped = resolve_for_scene(load_config("gaussiands", None, ["gaussiands.losses.depth=false", "gaussiands.losses.ds=false"]), _scene())
    assert "nothing uses it" in dropped["priors.depth"]
