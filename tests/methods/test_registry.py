"""The method registry: one registration makes a method known to the CLI, the config check, the
resolver and the report order; fit() and a grid build the same priors request (same cache entry)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from gsbench.config import load_config
from gsbench.errors import InputError
from gsbench.methods import registry
from gsbench.methods.base import Method
from gsbench.methods.registry import resolve_for_scene
from gsbench.runs.training import train_method


class DummyMethod(Method):
    """A method that needs nothing; only here to be registered."""

    name = "dummy-test"

    def train_phases(self, scene, run_dir: Path, config: dict, resume=None, progress: bool = True):  # pragma: no cover
        raise AssertionError("not trained in these tests")


def _resolve_dummy(cfg: dict, scene, drop) -> None:
    drop("priors.depth", "method dummy-test needs no priors")


def _budget_dummy(cfg: dict) -> dict:
    return {"rgb_steps": int(cfg["train"]["iterations"]), "semantic_steps": 0, "schedule": "none"}


def _uses_dummy(cfg: dict) -> dict:
    return {"depth_prior": False, "semantics": False}


@pytest.fixture
def dummy():
    spec = registry.register(registry.MethodSpec(
        name="dummy-test", target=f"{__name__}:DummyMethod", label="Dummy", section=None,
        resolve=f"{__name__}:_resolve_dummy", uses=f"{__name__}:_uses_dummy",
        budget=f"{__name__}:_budget_dummy"))
    yield spec
    registry.unregister("dummy-test")


@pytest.fixture(scope="module")
def tiny_scene(tmp_path_factory):
    from gsbench.datasets import load_scene
    from gsbench.datasets.synthetic import make_scene
    path = make_scene("tabletop-small", tmp_path_factory.mktemp("reg") / "scene", views=6, resolution=(32, 24))
    return load_scene(path)


# ---------------------------------------------------------------------------- one registration
def test_builtin_methods_in_report_order():
    assert tuple(registry.METHODS) == ("vanilla", "twostage", "lift", "grouping", "gaussiands")
    for name in registry.METHODS:
        assert registry.get_method(name).name == name


def test_a_registered_method_is_a_cli_choice_and_validates(dummy, tiny_scene):
    from gsbench.cli import build_parser
    argv = ["train", "--method", "dummy-test", "--scene", "S", "--out", "O"]
    args = build_parser().parse_args(argv)
    assert args.method == "dummy-test"
    assert "dummy-test" in build_parser()._subparsers._group_actions[0].choices["train"].format_help()
    cfg = load_config("dummy-test", "cpu-small", ["train.iterations=3"])
    assert cfg["method"] == "dummy-test"
    assert registry.get_method("dummy-test") is DummyMethod
    res, dropped = resolve_for_scene(cfg, tiny_scene)
    assert dropped == {"priors.depth": "method dummy-test needs no priors",
                       "semantic": "method dummy-test does not read it"}
    assert registry.priors_request(cfg, tiny_scene) is None
    from gsbench.reports.studies import ordered_methods

    assert ordered_methods(["dummy-test", "gaussiands", "zzz", "vanilla"]) == [
        "vanilla",
        "gaussiands",
        "dummy-test",
        "zzz",
    ]


def test_an_unregistered_method_is_refused(dummy):
    from gsbench.cli import build_parser
    registry.unregister("dummy-test")
    with pytest.raises(SystemExit):
        build_parser().parse_args(["train", "--method", "dummy-test", "--scene", "S", "--out", "O"])
    with pytest.raises(InputError, match="unknown method 'dummy-test'"):
        load_config("dummy-test")


def test_a_name_registers_once(dummy):
    with pytest.raises(ValueError, match="already registered"):
        registry.register(dummy)


def test_a_spec_names_its_code_as_strings():
    """Specs are data (gsbench/method_table.py, ground floor): a callable is refused, not stored."""
    with pytest.raises(ValueError, match="resolve must be 'module:attribute'"):
        registry.register(registry.MethodSpec(name="callable-test", target=f"{__name__}:DummyMethod", label="x",
                                              section=None, resolve=_resolve_dummy,  # type: ignore[arg-type]
                                              uses=f"{__name__}:_uses_dummy",
        budget=f"{__name__}:_budget_dummy"))
    assert "callable-test" not in registry.METHODS


def test_a_class_whose_name_disagrees_is_refused():
    registry.register(registry.MethodSpec(name="other-name", target=f"{__name__}:DummyMethod", label="x",
                                          section=None, resolve=f"{__name__}:_resolve_dummy",
                                          uses=f"{__name__}:_uses_dummy",
        budget=f"{__name__}:_budget_dummy"))
    try:
        with pytest.raises(TypeError, match="registered as 'other-name'"):
            registry.get_method("other-name")
    finally:
        registry.unregister("other-name")


def test_a_missing_section_is_named(tiny_scene):
    cfg = load_config("twostage", "cpu-small")
    del cfg["twostage"]
    with pytest.raises(InputError, match="no 'twostage' section"):
        resolve_for_scene(cfg, tiny_scene)


# ---------------------------------------------------------------------------- grid request == fit request
class _Stop(Exception):
    pass


CONFIGS = [
    [],
    ["semantic.loss=false"],
    ["gaussiands.losses.depth=false", "gaussiands.losses.ds=false"],
    ["priors.depth.provider=none", "train.max_width=16"],
    ["priors.ordering=random", "seed=3"],
]


@pytest.mark.parametrize("overrides", CONFIGS, ids=lambda o: ",".join(o) or "default")
@pytest.mark.parametrize("method", ["vanilla", "twostage", "grouping", "gaussiands"])
def test_fit_asks_for_the_priors_the_grid_prepares(method, overrides, tiny_scene, tmp_path, monkeypatch):
    """What fit() passes to prepare_priors is what the grid's request says (vanilla: nothing at all)."""
    import gsbench.methods.base as P  # where fit_priors looks prepare_priors up
    from gsbench.camera import training_size
    assert set(registry.METHODS) >= {"vanilla", "twostage", "gaussiands"}
    cache = tmp_path / "cache"
    cfg = load_config(method, "cpu-small", ["train.iterations=1", "train.eval_views=0", "backend=torch",
                                            f"priors.cache_dir={cache}"] + overrides)
    asked = []
    (tmp_path / "run").mkdir()

    def record(scene, priors_cfg, view_ids, size, cache_dir, **kw):
        asked.append({"scene_path": str(scene.path), "priors": priors_cfg, "view_ids": list(view_ids),
                      "size": list(size), "need_depth": kw["need_depth"], "need_sem": kw["need_masks"],
                      "per_frame": kw["per_frame_masks"], "seed": kw["seed"], "cache_dir": str(cache_dir)})
        assert kw["need_masks"] == kw["need_features"]
        raise _Stop

    monkeypatch.setattr(P, "prepare_priors", record)
    grid_req = registry.priors_request(cfg, tiny_scene.path)          # what a grid computes from the cell
    resolved, _ = resolve_for_scene(cfg, tiny_scene)                  # what gsbench train hands to fit()
    try:
        train_method(registry.get_method(method)(), tiny_scene, tmp_path / "run", resolved, progress=False)
    except _Stop:
        pass
    if grid_req is None:
        assert all(not (a["need_depth"] or a["need_sem"]) for a in asked)
        return
    assert len(asked) == 1
    fit_req = asked[0]
    assert fit_req.pop("cache_dir") == str(cache)
    assert json.dumps(fit_req, sort_keys=True) == json.dumps(grid_req, sort_keys=True)
    # and the request is what the scene and config say, not only self-consistent
    w, h = training_size(tiny_scene.cameras[tiny_scene.train_ids[0]], resolved["train"]["max_width"])
    assert grid_req["size"] == [w, h] and grid_req["view_ids"] == sorted(tiny_scene.train_ids)
    assert grid_req["per_frame"] is (method == "twostage")
    if method == "twostage":
        assert grid_req["need_depth"] is False


def test_the_grid_entry_is_a_cache_hit_for_fit(tiny_scene, tmp_path):
    """Priors computed from the grid's request are found in the cache by fit_priors."""
    from gsbench.methods.base import fit_priors
    from gsbench.priors import prepare_priors
    cfg = load_config("gaussiands", "cpu-small", ["train.max_width=16", f"priors.cache_dir={tmp_path / 'cache'}"])
    req = registry.priors_request(cfg, tiny_scene.path)
    assert req is not None and req["need_depth"] and req["need_sem"]
    first = prepare_priors(
        tiny_scene,
        req["priors"],
        req["view_ids"],
        tuple(req["size"]),
        Path(req["priors"]["cache_dir"]),
        need_depth=req["need_depth"],
        need_masks=req["need_sem"],
        need_features=req["need_sem"],
        per_frame_masks=req["per_frame"],
        seed=req["seed"],
        progress=False,
    )
    assert not any(v["hit"] for v in first.cache.values())
    resolved, _ = resolve_for_scene(cfg, tiny_scene)
    again = fit_priors(tiny_scene, resolved, tmp_path / "run", progress=False)
    assert set(again.cache) == {"depth", "masks", "mask-stats", "features"}
    assert all(v["hit"] for v in again.cache.values())
    assert {k: v["key"] for k, v in again.cache.items()} == {k: v["key"] for k, v in first.cache.items()}


class _FakeEntryPoint:
    """What importlib.metadata gives for one entry point of the gsbench.methods group."""

    def __init__(self, name: str, value: str, load):
        self.name, self.value, self._load = name, value, load
        self.dist = type("Dist", (), {"name": "fake-dist"})()

    def load(self):
        return self._load()


@pytest.fixture
def fresh_table(monkeypatch):
    """The method table emptied, to be loaded again with the entry points a test gives."""
    from gsbench import method_table as mt
    monkeypatch.setattr(mt, "_REGISTRY", {})
    monkeypatch.setattr(mt, "_LOADED", False)
    return mt


def test_an_entry_point_registers_a_method_after_the_builtins(fresh_table, monkeypatch):
    spec = registry.MethodSpec(name="ep-test", target=f"{__name__}:DummyMethod", label="EP", section="ep_test",
                               resolve=f"{__name__}:_resolve_dummy", uses=f"{__name__}:_uses_dummy",
                               budget=f"{__name__}:_budget_dummy", defaults={"alpha": 1.5})
    eps = [_FakeEntryPoint("ep-test", "pkg.spec:SPEC", lambda: spec)]
    monkeypatch.setattr(fresh_table, "entry_points", lambda group: eps if group == "gsbench.methods" else [])
    assert list(fresh_table.METHODS) == ["vanilla", "twostage", "lift", "grouping", "gaussiands", "ep-test"]
    assert fresh_table.section_defaults()["ep_test"] == {"alpha": 1.5}
    cfg = load_config("ep-test", None, ["ep_test.alpha=2.5"])        # its own section is a checked key
    assert cfg["ep_test"]["alpha"] == 2.5
    with pytest.raises(InputError, match="ep_test.alpah"):
        load_config("ep-test", None, ["ep_test.alpah=1"])


def test_a_broken_entry_point_is_one_error_naming_it(fresh_table, monkeypatch):
    def boom():
        raise ModuleNotFoundError("No module named 'pkg'")
    eps = [_FakeEntryPoint("broken", "pkg.spec:SPEC", boom)]
    monkeypatch.setattr(fresh_table, "entry_points", lambda group: eps)
    with pytest.raises(InputError, match=r"entry point 'broken' = 'pkg.spec:SPEC' of distribution fake-dist.*"
                                         r"cannot be loaded: ModuleNotFoundError"):
        list(fresh_table.METHODS)


def test_an_entry_point_naming_something_else_is_refused(fresh_table, monkeypatch):
    eps = [_FakeEntryPoint("odd", "pkg.spec:SPEC", lambda: {"name": "odd"})]
    monkeypatch.setattr(fresh_table, "entry_points", lambda group: eps)
    with pytest.raises(InputError, match="names dict, not a gsbench MethodSpec"):
        list(fresh_table.METHODS)
