"""A run is read only under its identity: `gsbench eval RUN` computes the run id again from
config.json (its config and scene fingerprint) and refuses, in one line, a config edited after
training or taken from another run. The resolver's switches (losses it turned off for the scene,
recorded in `dropped`) are undone first: the run id is the one of the config as given to train."""
from __future__ import annotations

import shutil

import pytest

from gsbench.cli import main
from gsbench.config import load_config, run_config, run_id
from gsbench.datasets import load_scene, scene_fingerprint
from gsbench.errors import InputError
from gsbench.evaluation.trained_run import check_identity
from gsbench.methods.registry import resolve_for_scene
from gsbench.store import read_json, write_json_atomic


def _as_written(method: str, sets: list[str], scene) -> dict:
    """config.json as train_run writes it: resolved for the scene, the run id of the config as given."""
    given = load_config(method, "cpu-small", sets)
    fp = scene_fingerprint(scene)
    cfg, _ = resolve_for_scene(given, load_scene(scene))
    cfg["scene"] = {"path": str(scene), "name": "s", "fingerprint": fp}
    cfg["run_id"] = run_id(given, fp)
    return cfg


def test_a_config_the_resolver_changed_still_gives_its_run_id(tiny_scene):
    cfg = _as_written("gaussiands", ["priors.depth.provider=none"], tiny_scene)
    assert cfg["gaussiands"]["losses"]["depth"] is False            # switched off by the resolver
    assert run_id(cfg, cfg["scene"]["fingerprint"]) != cfg["run_id"]  # so the plain recomputation differs
    check_identity(cfg, run_config(cfg, "config.json"), "config.json")


@pytest.mark.parametrize("key,value", [("seed", 7), ("gaussiands.lambdas.sem", 0.5), ("train.iterations", 3),
                                       ("scene.fingerprint", "0" * 16)])
def test_an_edited_config_is_refused(tiny_scene, key, value):
    cfg = _as_written("gaussiands", ["priors.depth.provider=none"], tiny_scene)
    *parents, leaf = key.split(".")
    d = cfg
    for p in parents:
        d = d[p]
    d[leaf] = value
    with pytest.raises(InputError, match=r"^config.json: the config does not give the run's id"):
        check_identity(cfg, run_config(cfg, "config.json"), "config.json")


def test_eval_refuses_an_edited_seed_in_one_line(tiny_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    cfg = read_json(run / "config.json")
    cfg["seed"] = int(cfg["seed"]) + 1
    write_json_atomic(run / "config.json", cfg)
    assert main(["eval", str(run), "--no-progress"]) == 1
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert lines[-1].startswith(f"gsbench eval: error: {run / 'config.json'}: the config does not give the run's id")
    assert not (run / "results.json").exists()


def test_eval_of_the_untouched_run_passes_the_check(tiny_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    assert main(["eval", str(run), "--no-progress", "--quiet"]) == 0
    assert read_json(run / "results.json")["run_id"] == read_json(run / "config.json")["run_id"]


def test_a_plugin_resolver_that_sets_values_keeps_its_runs_readable_and_edits_refused(tmp_path):
    """A resolver that sets a value (here train.lambda_dssim from the method's own section, as a plugin's
    may) makes the run id's pre-resolver config unrecoverable: the config's own id, recorded at training
    in train_summary.json, is what eval checks."""
    cfg = {"method": "vanilla", "seed": 0, "train": {"lambda_dssim": 0.5}, "scene": {"fingerprint": "f" * 16},
           "run_id": "0123456789abcdef"}
    summary = {"run_id": "0123456789abcdef", "resolved_config_id": run_id(cfg, "f" * 16)}
    check_identity(dict(cfg), cfg, tmp_path / "config.json", summary)
    edited = {**cfg, "seed": 1}
    with pytest.raises(InputError, match=r"config.json: the config does not give the run's id 0123456789abcdef "
                                         r"\(the config it trained with has id"):
        check_identity(edited, edited, tmp_path / "config.json", summary)
