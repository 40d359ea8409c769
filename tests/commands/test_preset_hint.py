"""`gsbench train` names the preset tuned on real photos when a synthetic-tuned one meets a real capture."""
from __future__ import annotations

import logging

import pytest

from gsbench.commands import train as train_command
from gsbench.config import load_config


def _real(tmp_path):
    scene = tmp_path / "capture"
    (scene / "images").mkdir(parents=True)
    return scene


def _synthetic(tmp_path):
    scene = tmp_path / "generated"
    scene.mkdir()
    (scene / "gsbench_scene.json").write_text("{}")
    return scene


@pytest.mark.parametrize("preset", ["cpu-small", "cpu-medium"])
def test_a_synthetic_preset_on_a_real_capture_names_the_real_one(tmp_path, preset):
    hint = train_command.preset_hint(preset, _real(tmp_path))
    assert hint is not None and f"--preset {preset}" in hint and "--preset cpu-real" in hint


@pytest.mark.parametrize("preset", [None, "cpu-real", "paper", "my-preset.yaml"])
def test_no_hint_for_other_presets(tmp_path, preset):
    assert train_command.preset_hint(preset, _real(tmp_path)) is None


def test_no_hint_on_a_generated_scene(tmp_path):
    assert train_command.preset_hint("cpu-medium", _synthetic(tmp_path)) is None


def test_the_hint_is_logged_before_training(tmp_path, monkeypatch, caplog):
    import gsbench.runs
    seen = []
    monkeypatch.setattr(gsbench.runs, "train_run", lambda *a, **k: seen.append(a) or (_ for _ in ()).throw(
        SystemExit(0)))
    args = train_command.argparse.Namespace(method="vanilla", scene=str(_real(tmp_path)), preset="cpu-medium",
                                            overrides=[], out=str(tmp_path / "run"), no_progress=True)
    with caplog.at_level(logging.WARNING, logger="gsbench.commands.train"), pytest.raises(SystemExit):
        train_command.run(args)
    assert seen and any("--preset cpu-real" in r.getMessage() for r in caplog.records)


def test_the_real_preset_exists_and_loads_for_every_method():
    for method in ("vanilla", "gaussiands", "twostage", "grouping"):
        cfg = load_config(method, "cpu-real")
        assert cfg["backend"] == "cpu" and cfg["train"]["max_width"] == 256
