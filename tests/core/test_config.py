"""Config loading, overrides, run ids and the per-scene resolver."""
import json

import numpy as np
import pytest

from gsbench.camera import Camera
from gsbench.config import load_config, parse_overrides, run_id
from gsbench.datasets.base import Scene
from gsbench.errors import InputError
from gsbench.methods.registry import resolve_for_scene, uses


def test_defaults_carry_the_paper_weights():
    c = load_config("gaussiands")
    assert c["gaussiands"]["lambdas"] == {"depth": 0.01, "tv": 1.5, "sem": 5.0, "ds": 1.0}
    assert c["semantic"]["latent_dim"] == 3 and c["train"]["iterations"] == 30000
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


@pytest.mark.parametrize(
    "bad",
    [
        ["train.iteration=5"],
        ["nokey=1"],
        ["train.iterations"],
        ["gaussiands.depth_formulation=foo"],
        ["semantic.latent_dim=0"],
        ["query.mode=both"],
    ],
)
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
    cfg, dropped = resolve_for_scene(load_config("gaussiands", None, ["priors.depth.provider=gt"]), _scene(depth=False))
    on = cfg["gaussiands"]["losses"]
    assert on["depth"] is False and on["ds"] is False and on["tv"] is True and cfg["semantic"]["loss"] is True
    assert "GT depth" in dropped["gaussiands.losses.depth"] and "priors.depth" in dropped
    # the sparse provider works from points
    cfg2, d2 = resolve_for_scene(load_config("gaussiands", None, ["priors.depth.provider=sparse"]), _scene(depth=False))
    assert cfg2["gaussiands"]["losses"]["depth"] is True and d2 == {}


def test_default_depth_rule_keeps_the_depth_terms_on_a_scene_with_only_points():
    # the default provider is the rule `auto`: no GT depth but sparse points -> sfm, the terms kept
    cfg, dropped = resolve_for_scene(load_config("gaussiands"), _scene(depth=False))
    assert cfg["priors"]["depth"]["provider"] == "auto"
    assert cfg["gaussiands"]["losses"]["depth"] is True and cfg["gaussiands"]["losses"]["ds"] is True
    assert dropped == {}
    # neither GT depth nor points: the terms are dropped, with what is missing named
    cfg2, d2 = resolve_for_scene(load_config("gaussiands"), _scene(depth=False, points=False))
    assert cfg2["gaussiands"]["losses"]["depth"] is False
    assert "no sparse points" in d2["gaussiands.losses.depth"] or "no sparse points" in d2["priors.depth"]


def test_resolver_drops_semantics_without_semantics():
    cfg, dropped = resolve_for_scene(load_config("gaussiands"), _scene(instances=False))
    on = cfg["gaussiands"]["losses"]
    assert cfg["semantic"]["loss"] is False and on["ds"] is False and on["depth"] is True
    assert "no semantics in the scene" in dropped["semantic.loss"] and "gaussiands.losses.ds" in dropped
    for part in ("priors.masks", "priors.features", "semantic.autoencoder", "semantic_channels"):
        assert "no semantics in the scene" in dropped[part]


def test_resolver_vanilla_twostage_and_formulation_none():
    cfg, dropped = resolve_for_scene(load_config("vanilla"), _scene())
    assert "priors.depth" in dropped and "does not read it" in dropped["semantic"]
    assert not any(uses(cfg).values())
    cfg, dropped = resolve_for_scene(load_config("twostage"), _scene())
    assert cfg["semantic"]["loss"] and uses(cfg) == {"depth_prior": False, "semantics": True}
    assert "priors.depth" in dropped and "semantic" not in dropped
    cfg, dropped = resolve_for_scene(load_config("gaussiands", None, ["gaussiands.depth_formulation=none"]), _scene())
    assert cfg["gaussiands"]["losses"]["depth"] is False and cfg["gaussiands"]["losses"]["ds"] is True
    assert "formulation=none" in dropped["gaussiands.losses.depth"]
    cfg, dropped = resolve_for_scene(
        load_config("gaussiands", None, ["gaussiands.losses.depth=false", "gaussiands.losses.ds=false"]), _scene()
    )
    assert "nothing uses it" in dropped["priors.depth"]


# ---------------------------------------------------------------------------- one override path
import argparse  # noqa: E402

from gsbench import config_keys  # noqa: E402
from gsbench.cli import build_parser  # noqa: E402
from gsbench.commands.ablate import grid_from_args  # noqa: E402
from gsbench.commands.train import config_from_args  # noqa: E402
from gsbench.config import default_tree, flatten, load_tree, shipped_presets, validate  # noqa: E402
from gsbench.grids import cell_config, load_grid  # noqa: E402

ONE_CELL_GRID = """study: custom
base:
  method: gaussiands
  preset: cpu-small
scenes: [tabletop-small]
seeds: [0]
"""


def _train_args(*argv: str) -> argparse.Namespace:
    return build_parser().parse_args(["train", "--method", "gaussiands", "--preset", "cpu-small", "--scene", "s",
                                      "--out", "o", *argv])


def _ablate_cell_config(tmp_path, *argv: str) -> dict:
    g = tmp_path / "one.yaml"
    g.write_text(ONE_CELL_GRID)
    args = build_parser().parse_args(["ablate", "--grid", str(g), "--out", str(tmp_path / "runs"), *argv])
    grid = grid_from_args(args)
    [cell] = grid.cells()
    cfg = cell_config(cell, tmp_path / "runs", grid.axis_keys)
    for k in ("study", "grid"):
        cfg.pop(k)
    cfg["priors"]["cache_dir"] = None
    return cfg


@pytest.mark.parametrize("train_argv, ablate_argv", [
    (["--set", "train.lr.color=1e-4", "--set", "gaussiands.losses.ds=false"],
     ["--set", "train.lr.color=1e-4", "gaussiands.losses.ds=false"]),
    (["--set", "train.lr.color=1e-4", "gaussiands.losses.ds=false"],
     ["--set", "train.lr.color=1e-4", "--set", "gaussiands.losses.ds=false"]),
])
def test_train_and_ablate_resolve_the_same_set_list(tmp_path, train_argv, ablate_argv):
    via_train = config_from_args(_train_args(*train_argv))
    via_ablate = _ablate_cell_config(tmp_path, *ablate_argv)
    assert via_train["train"]["lr"]["color"] == 1e-4 and isinstance(via_train["train"]["lr"]["color"], float)
    assert via_train["gaussiands"]["losses"]["ds"] is False
    assert via_ablate["seed"] == via_train["seed"] == 0
    assert via_train == via_ablate
    # both keys are kept when --set is repeated (ablate used to keep only the last one)
    assert via_ablate["train"]["lr"]["color"] == 1e-4 and via_ablate["gaussiands"]["losses"]["ds"] is False


def test_a_wrong_typed_bool_is_refused_by_train_and_ablate(tmp_path, capsys):
    from gsbench.cli import main
    with pytest.raises(InputError, match="gaussiands.losses.depth must be true/false, got 3"):
        config_from_args(_train_args("--set", "gaussiands.losses.depth=3"))
    with pytest.raises(InputError, match="gaussiands.losses.depth must be true/false, got 3"):
        _ablate_cell_config(tmp_path, "--set", "train.iterations=5", "gaussiands.losses.depth=3")
    g = tmp_path / "one.yaml"
    assert main(["ablate", "--grid", str(g), "--out", str(tmp_path / "r"), "--dry-run",
                 "--set", "gaussiands.losses.depth=3"]) == 1
    assert main(["train", "--method", "vanilla", "--scene", str(tmp_path), "--out", str(tmp_path / "r2"),
                 "--set", "gaussiands.losses.depth=3"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("gaussiands.losses.depth must be true/false" in line for line in err)


@pytest.mark.parametrize("item, expect", [
    ("train.lr.position_init=-1", "train.lr.position_init=-1 is out of range: must be > 0"),
    ("train.lr.color=0", "train.lr.color=0 is out of range: must be > 0"),
    ("train.lambda_dssim=7", "train.lambda_dssim=7 is out of range: must be in [0, 1]"),
    ("train.iterations=-5", "train.iterations=-5 is out of range: must be >= 1"),
    ("train.iterations=0", "train.iterations=0 is out of range: must be >= 1"),
    ("gaussiands.lambdas.sem=-3", "gaussiands.lambdas.sem=-3 is out of range: must be >= 0"),
    ("priors.masks.min_iou=1.5", "priors.masks.min_iou=1.5 is out of range: must be in [0, 1]"),
    ("train.lambda_dssim=.nan", "train.lambda_dssim=nan is out of range"),
    ("train.lr.color=.inf", "train.lr.color=inf is out of range"),
    ("backend=vulkan", "backend='vulkan' is out of range: must be one of auto, torch, cpu, gsplat"),
    ("priors.depth.noise.type=fog", "must be one of null, gaussian, poisson, motion_blur, salt_pepper"),
    ("train.max_width=0", "train.max_width=0 is out of range: must be >= 1"),
    ("train.iterations=1.5", "train.iterations must be a whole number"),
    ("train.iterations=null", "train.iterations cannot be null"),
    ("semantic.latent_dim='3'", "semantic.latent_dim must be a number"),
])
def test_out_of_range_and_wrong_type_name_key_and_range(item, expect):
    with pytest.raises(InputError) as e:
        load_config("gaussiands", None, [item])
    assert expect in str(e.value)


def test_values_inside_the_ranges_are_kept():
    c = load_config(
        "gaussiands",
        None,
        [
            "train.lambda_dssim=0",
            "train.lambda_dssim=1",
            "train.iterations=3e4",
            "gaussiands.lambdas.sem=0",
            "train.max_width=null",
            "priors.depth.noise.type=null",
            "gaussiands.lambdas.tv=2",
        ],
    )
    assert c["train"]["lambda_dssim"] == 1.0 and c["gaussiands"]["lambdas"]["sem"] == 0.0
    assert c["train"]["iterations"] == 30000 and isinstance(c["train"]["iterations"], int)
    assert c["gaussiands"]["lambdas"]["tv"] == 2.0 and isinstance(c["gaussiands"]["lambdas"]["tv"], float)


def test_unknown_key_suggests_close_matches():
    with pytest.raises(InputError, match=r"unknown config key 'train.lambda_dsim'.*did you mean train.lambda_dssim"):
        load_config("gaussiands", None, ["train.lambda_dsim=0.1"])
    with pytest.raises(InputError, match=r"unknown config key 'train.lr'.*a section.*train.lr.position_init"):
        load_config("gaussiands", None, ["train.lr=0.1"])


def test_grid_yaml_reads_1e4_as_a_number_in_base_axes_and_sweeps(tmp_path):
    g = tmp_path / "g.yaml"
    g.write_text("""study: custom
base:
  method: gaussiands
  preset: cpu-small
  set: {train.lr.color: 1e-4}
scenes: [tabletop-small]
seeds: [0]
axes:
  train.lr.position_init: [1e-4, 2.0e-4]
sweeps:
  - axes: {train.lr.opacity: [5E-2]}
""")
    grid = load_grid(g)
    cells = grid.cells()
    assert grid.base_set["train.lr.color"] == 1e-4
    assert sorted(c.overrides.get("train.lr.position_init", 0.0) for c in cells) == [0.0, 1e-4, 2e-4]
    cfgs = [cell_config(c, tmp_path, grid.axis_keys) for c in cells]
    assert all(isinstance(c["train"]["lr"]["color"], float) and c["train"]["lr"]["color"] == 1e-4 for c in cfgs)
    assert {c["grid"]["train.lr.opacity"] for c in cfgs} == {0.05}
    g.write_text(g.read_text().replace("[5E-2]", "['5E-2']"))      # a quoted number stays a string: refused
    with pytest.raises(InputError, match="train.lr.opacity must be a number"):
        load_grid(g)


def test_a_preset_file_works_in_train_and_as_a_grid_base_preset(tmp_path):
    (tmp_path / "mine.yaml").write_text("train:\n  iterations: 42\n  lr:\n    color: 3e-3\n")
    c = config_from_args(build_parser().parse_args(["train", "--method", "vanilla", "--scene", "s", "--out", "o",
                                                    "--preset", str(tmp_path / "mine.yaml")]))
    assert c["train"]["iterations"] == 42 and c["train"]["lr"]["color"] == 3e-3
    (tmp_path / "g.yaml").write_text(ONE_CELL_GRID.replace("preset: cpu-small", "preset: mine.yaml"))
    grid = load_grid(tmp_path / "g.yaml")          # relative to the grid file
    [cell] = grid.cells()
    cfg = cell_config(cell, tmp_path, grid.axis_keys)
    assert cfg["train"]["iterations"] == 42 and cfg["train"]["lr"]["color"] == 3e-3
    (tmp_path / "bad.yaml").write_text("train:\n  lambda_dssim: 2\n")
    with pytest.raises(InputError, match=r"bad.yaml: train.lambda_dssim=2 is out of range"):
        load_config("vanilla", str(tmp_path / "bad.yaml"))


def test_every_rule_names_a_key_of_default_yaml_and_shipped_configs_pass():
    leaves = flatten(default_tree())
    assert set(config_keys.RULES) <= set(leaves)
    from gsbench.method_table import method_rules
    assert set(method_rules()) <= set(leaves)          # a spec's rules name keys of its own section
    validate(default_tree())
    for preset in shipped_presets():
        for m in config_keys.METHODS:
            validate(load_config(m, preset))
    assert load_tree("cpu-small")["train"]["iterations"] == 500


def test_declared_choices_agree_with_the_code_that_consumes_them():
    """One declaration per choice list: the consumers use config_keys' object (or one derived from it);
    a method's own lists are its spec's, kept equal to the code that implements them."""
    from gsbench.datasets.noise import NOISE_KINDS, SEVERITIES
    from gsbench.datasets.splits import HOLDOUT_CHOICES
    from gsbench.evaluation.frames import RESOLUTIONS
    from gsbench.evaluation.segmentation import PROTOCOLS
    from gsbench.methods.gaussiands import spec as gaussiands_spec
    from gsbench.metrics.lerf import LERF_KERNEL_MODES
    from gsbench.priors.depth import DEPTH_PROVIDERS
    from gsbench.priors.features import FEATURE_PROVIDERS
    from gsbench.priors.ordering import ORDERINGS
    from gsbench.priors.pipeline import MASK_PROVIDERS, PROPAGATORS
    from gsbench.priors.propagation import NEW_OBJECT_RULES
    from gsbench.render import BACKENDS
    from gsbench.train.losses import DEPTH_FORMULATIONS, DS_AVERAGES
    for used, declared in ((HOLDOUT_CHOICES, "HOLDOUTS"), (RESOLUTIONS, "EVAL_RESOLUTIONS"),
                           (LERF_KERNEL_MODES, "LERF_KERNEL_MODES"), (DEPTH_PROVIDERS, "DEPTH_PROVIDERS"),
                           (MASK_PROVIDERS, "MASK_PROVIDERS"), (FEATURE_PROVIDERS, "FEATURE_PROVIDERS"),
                           (PROPAGATORS, "PROPAGATORS"), (NEW_OBJECT_RULES, "NEW_OBJECT_RULES"),
                           (ORDERINGS, "ORDERINGS"), (PROTOCOLS, "PROTOCOLS"), (SEVERITIES, "NOISE_SEVERITIES")):
        assert used is getattr(config_keys, declared), declared
    assert (None, *NOISE_KINDS) == config_keys.NOISE_TYPES and ("auto", *BACKENDS) == config_keys.BACKENDS
    assert set(gaussiands_spec.DEPTH_FORMULATIONS) == set(DEPTH_FORMULATIONS)   # the method's own keys: its spec
    assert set(gaussiands_spec.DS_AVERAGES) == set(DS_AVERAGES)


def test_one_config_hash_rule_for_run_ids_and_config_keys():
    """run_id and config_key read one canonical config: key order and where-things-are-kept keys do
    not change them, a training key does, and the seed changes the run id only."""
    from gsbench.config import config_key, run_id
    a = load_config("gaussiands", "cpu-small")
    b = json.loads(json.dumps(a))
    b = dict(reversed(list(b.items())))                       # another key order
    b["priors"]["cache_dir"] = "/elsewhere/cache"             # where the cache is kept
    b["train"]["data_on"] = "host"                            # where the data is kept
    b["dropped"] = {"priors.depth": "a reason"}               # bookkeeping
    assert run_id(a, "fp") == run_id(b, "fp") and config_key(a) == config_key(b)
    c = json.loads(json.dumps(a))
    c["train"]["iterations"] += 1
    assert run_id(a, "fp") != run_id(c, "fp") and config_key(a) != config_key(c)
    s = json.loads(json.dumps(a))
    s["seed"] = 7
    assert run_id(a, "fp") != run_id(s, "fp") and config_key(a) == config_key(s)
    assert run_id(a, "fp") != run_id(a, "other scene")


def test_the_yaml_reader_gives_pythons_parser_trees_for_every_shipped_file():
    """load_yaml parses with libyaml where PyYAML has it; PyYAML's Python parser, with the same
    float rule, must read every shipped config, preset and grid file to the same tree."""
    from pathlib import Path

    import yaml

    import gsbench
    from gsbench import config, yaml_reader

    class PythonLoader(yaml.SafeLoader):      # the same resolvers, PyYAML's Python parser
        yaml_implicit_resolvers = yaml_reader._Loader.yaml_implicit_resolvers

    load_yaml = config.load_yaml
    files = sorted(Path(gsbench.__file__).parent.rglob("*.yaml"))
    assert len(files) >= 20
    for f in files:
        text = f.read_text()
        assert load_yaml(text) == yaml.load(text, Loader=PythonLoader), f
    text = "a: 1e-4\nb: '1e-4'\nc: -2.5E+3\nd: [1, 2]\ne: null\nf: yes\ng: 0x10\nh: 1_000"
    assert load_yaml(text) == yaml.load(text, Loader=PythonLoader) == {
        "a": 1e-4, "b": "1e-4", "c": -2500.0, "d": [1, 2], "e": None, "f": True, "g": 16, "h": 1000}
