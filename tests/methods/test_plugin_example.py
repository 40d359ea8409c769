"""A method from an installed package: tests/plugin_example is pip-installed into a folder of its own
and its `example_l1` method (registered through the `gsbench.methods` entry-point group, with its own
config section) goes through train, eval, ablate and report in fresh processes."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from paths import REPO_ROOT

PLUGIN = REPO_ROOT / "tests" / "plugin_example"
SHORT = ["--preset", "cpu-small", "--set", "train.iterations=2", "train.eval_every=0", "train.checkpoint_every=0"]


@pytest.fixture(scope="module")
def plugin_env(tmp_path_factory) -> dict:
    """The environment of a process that sees the installed example plugin."""
    src = tmp_path_factory.mktemp("plugin_src") / "plugin_example"
    shutil.copytree(PLUGIN, src)     # build outside the repository (no build/ or egg-info left there)
    target = tmp_path_factory.mktemp("plugin_site")
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                    "--no-index", "--target", str(target), str(src)], check=True, capture_output=True, timeout=300)
    env = dict(os.environ)
    env["PYTHONPATH"] = str(target) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def _gsbench(env: dict, *args: str) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name("gsbench")
    res = subprocess.run([str(exe), *args], env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, f"gsbench {' '.join(args)}:\n{res.stdout[-2000:]}\n{res.stderr[-3000:]}"
    return res


def test_the_plugin_method_is_listed_only_when_installed(plugin_env):
    exe = str(Path(sys.executable).with_name("gsbench"))
    with_plugin = subprocess.run([exe, "train", "--help"], env=plugin_env, capture_output=True, text=True).stdout
    without = subprocess.run([exe, "train", "--help"], capture_output=True, text=True).stdout
    assert "example_l1" in with_plugin and "example_l1" not in without


def test_plugin_method_trains_evaluates_ablates_and_reports(plugin_env, tiny_scene, tmp_path):
    run = tmp_path / "run"
    _gsbench(plugin_env, "train", "--method", "example_l1", "--scene", str(tiny_scene), "--out", str(run),
             "--no-progress", *SHORT, "example_l1.lambda_dssim=0.1")
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["method"] == "example_l1"
    assert cfg["example_l1"]["lambda_dssim"] == 0.1 and cfg["train"]["lambda_dssim"] == 0.1  # its resolver ran
    _gsbench(plugin_env, "eval", str(run), "--no-progress")
    res = json.loads((run / "results.json").read_text())
    assert res["method"] == "example_l1" and res["metrics"]["psnr"] is not None
    assert res["budget"] == {"rgb_steps": 2, "semantic_steps": 0, "schedule": "none"}

    grid = tmp_path / "plugin_grid.yaml"
    grid.write_text(f"""study: plugin_check
description: the example plugin against vanilla
base:
  preset: cpu-small
  set: {{train.iterations: 2, train.eval_every: 0, train.checkpoint_every: 0}}
scenes: [{{path: {tiny_scene}}}]
seeds: [0]
axes:
  method: [vanilla, example_l1]
""")
    runs = tmp_path / "runs"
    _gsbench(plugin_env, "ablate", "--grid", str(grid), "--out", str(runs), "--executor", "serial", "--no-progress")
    methods = sorted(json.loads(p.read_text())["method"] for p in runs.rglob("results.json"))
    assert methods == ["example_l1", "vanilla"]

    report = tmp_path / "report"
    _gsbench(plugin_env, "report", str(runs), "--out", str(report), "--no-progress")
    html = (report / "index.html").read_text()
    assert "Example L1 (plugin)" in html and "3DGS (vanilla)" in html
