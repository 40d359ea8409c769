"""Hostile inputs: configs, presets, grid files, YAML and JSON documents, run folders' config.json (the battery:
gsbench/commands/hostile/__init__.py).

Every YAML text is read by gsbench.config.load_yaml (a size, a node count with aliases expanded, a depth)
and every JSON file by gsbench.store.read_json (a size, a depth); config values are held to their rules
(gsbench/config_keys.py, list lengths and elements included), and a run folder's config.json must be an
object that names its model's method. Each case breaks one of these and names what the error must say.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, Optional

from gsbench.collect import read_collected
from gsbench.commands.hostile import Hostile, tiny_run, tiny_scene
from gsbench.store import MAX_JSON_BYTES, MAX_JSON_DEPTH
from gsbench.yaml_reader import MAX_YAML_DEPTH, MAX_YAML_NODES

AREA = "config"
DEEP_JSON = "[" * 100_000 + "]" * 100_000      # 100,000 levels: past Python's recursion limit
TRAIN_ARGS = ["--method", "vanilla", "--preset", "cpu-small", "--set", "train.iterations=2", "--set",
              "train.eval_every=0", "--no-progress", "--quiet"]
BOMB = f"more than {MAX_YAML_NODES} nodes"
TOO_DEEP_JSON = f"JSON nested deeper than {MAX_JSON_DEPTH} levels"


def alias_bomb(levels: int = 9, width: int = 9) -> str:
    """A flow-style YAML "billion laughs": a list of `levels` anchors, each a list of `width` aliases of the
    one before, so a few hundred characters stand for width ** levels leaves."""
    parts = ["&a0 [" + ", ".join(["lol"] * width) + "]"]
    parts += [f"&a{i} [" + ", ".join([f"*a{i - 1}"] * width) + "]" for i in range(1, levels)]
    return "[" + ", ".join(parts) + "]"


def _grid(field: str, value: str) -> Callable[[Path], list[str]]:
    """A grid file whose `field` holds `value` (YAML text), planned with --dry-run."""
    def build(folder: Path) -> list[str]:
        grid = folder / "grid.yaml"
        grid.write_text(f"study: tiny-test\n{field}: {value}\nbase: {{method: vanilla}}\nscenes: [tabletop-small]\n")
        return ["ablate", "--grid", str(grid), "--out", str(folder / "runs"), "--dry-run"]
    return build


def _preset(text: str) -> Callable[[Path], list[str]]:
    """`gsbench train` with a preset file holding `text`."""
    def build(folder: Path) -> list[str]:
        preset = folder / "preset.yaml"
        preset.write_text(text)
        scene = tiny_scene(folder / "scene")
        return ["train", "--method", "vanilla", "--scene", str(scene), "--preset", str(preset),
                "--out", str(folder / "run"), "--no-progress"]
    return build


def _big_preset(folder: Path) -> list[str]:
    """A preset file of 2 MiB (sparse: nothing is written), over the YAML size budget."""
    preset = folder / "preset.yaml"
    with open(preset, "wb") as f:
        f.truncate(2 * 1024 * 1024)
    return ["train", "--method", "vanilla", "--scene", str(folder / "scene"), "--preset", str(preset),
            "--out", str(folder / "run")]


def _set(item: str) -> Callable[[Path], list[str]]:
    """`gsbench train --set item`."""
    def build(folder: Path) -> list[str]:
        scene = tiny_scene(folder / "scene")
        return ["train", "--scene", str(scene), "--out", str(folder / "run"), *TRAIN_ARGS, "--set", item]
    return build


def _scene_file(rel: str, text: str) -> Callable[[Path], list[str]]:
    """`gsbench train` on a scene copy whose file `rel` holds `text`."""
    def build(folder: Path) -> list[str]:
        scene = tiny_scene(folder / "scene")
        (scene / rel).write_text(text)
        return ["train", "--scene", str(scene), "--out", str(folder / "run"), *TRAIN_ARGS]
    return build


def _deep_label(folder: Path) -> list[str]:
    """Predicted masks scored against a LERF-OVS label folder whose first label is 100,000 levels deep."""
    labels = tiny_scene(folder / "scene") / "label" / "tabletop-small"
    sorted(labels.glob("frame_*.json"))[0].write_text(DEEP_JSON)
    (folder / "pred").mkdir()
    return ["eval", "--masks", str(folder / "pred"), "--layout", str(labels), "--protocol", "lerf",
            "--out", str(folder / "out"), "--no-progress"]


def _run_config(edit: Callable[[dict], object], method: str = "vanilla") -> Callable[[Path], list[str]]:
    """`gsbench eval` on a finished run of `method` whose config.json becomes `edit(config)`."""
    def build(folder: Path) -> list[str]:
        run = tiny_run(folder / "run", method)
        cfg = json.loads((run / "config.json").read_text())
        (run / "config.json").write_text(json.dumps(edit(cfg)))
        return ["eval", str(run), "--no-progress"]
    return build


def _other_method(cfg: dict) -> dict:
    return {**cfg, "method": "vanilla"}


def _edited(path: str, value: object) -> Callable[[dict], dict]:
    """config.json with the dotted key `path` set to `value` (a hand edit after training)."""
    def edit(cfg: dict) -> dict:
        *parents, leaf = path.split(".")
        d = cfg
        for p in parents:
            d = d[p]
        d[leaf] = value
        return cfg
    return edit


def _without(key: str) -> Callable[[dict], dict]:
    return lambda cfg: {k: v for k, v in cfg.items() if k != key}


def _interrupted_run(folder: Path) -> list[str]:
    """A run whose status.json says it was interrupted (Ctrl-C or SIGTERM) before it finished."""
    run = tiny_run(folder / "run")
    (run / "status.json").write_text(json.dumps({"state": "interrupted", "message": "terminated (SIGTERM)"}))
    return ["eval", str(run), "--no-progress"]


def _collect(write_bad: Callable[[Path], None]) -> Callable[[Path], list[str]]:
    """`gsbench collect` on a good run's results.json and a bad one written by `write_bad(path)`."""
    def build(folder: Path) -> list[str]:
        good = folder / "runs" / "good" / "results.json"
        good.parent.mkdir(parents=True)
        good.write_text(json.dumps({"run_id": "good", "method": "vanilla", "scene": "s", "metrics": {"psnr": 20.0}}))
        bad = folder / "runs" / "bad" / "results.json"
        bad.parent.mkdir()
        write_bad(bad)
        return ["collect", str(folder / "runs")]
    return build


def _huge_file(path: Path) -> None:
    """A file just over the JSON size budget (sparse: nothing is written)."""
    with open(path, "wb") as f:
        f.truncate(MAX_JSON_BYTES + 1)


def _failed_row(what: str) -> Callable[[Path, int, str], Optional[str]]:
    """collect's answer to one unreadable results.json: a warning naming it, and in the table a failed row
    whose reason names it next to the good run's rows."""
    def check(folder: Path, code: int, err: str) -> Optional[str]:
        bad = str(folder / "runs" / "bad" / "results.json")
        if bad not in err or what not in err:
            return f"no warning naming {bad} and {what!r}"
        table = next((p for p in (folder / "runs").glob("collected.*")), None)
        if table is None:
            return "no collected table written"
        df = read_collected(table)
        failed = df[(df["status"] == "failed") & df["reason"].fillna("").str.contains(bad, regex=False)]
        good = df[(df["run_id"] == "good") & (df["metric"] == "psnr") & (df["value"] == 20.0)]
        if len(failed) != 1 or len(good) != 1:
            return f"{len(failed)} failed rows naming the bad file and {len(good)} psnr rows of the good run"
        return None
    return check


def _case(name: str, build: Callable[[Path], list[str]], *expect: str, **kw) -> Hostile:
    return Hostile(AREA, name, build, tuple(expect), **kw)


CASES: list[Hostile] = [
    # YAML: a "billion laughs" (9 levels of 9 aliases) wherever a YAML text enters
    _case("grid description: alias bomb", _grid("description", alias_bomb()), "grid.yaml", BOMB),
    _case("grid seeds: alias bomb (5 levels)", _grid("seeds", alias_bomb(5)), "grid.yaml", BOMB),
    _case("grid seeds: 4 levels of aliases, under the budget", _grid("seeds", alias_bomb(4)), "grid.yaml",
          "seeds must be integers"),
    _case("preset value: alias bomb", _preset(f"priors.masks.model_overrides: {alias_bomb()}\n"), "preset.yaml",
          BOMB),
    _case("--set value: alias bomb", _set(f"train.background={alias_bomb()}"), "--set train.background", BOMB),
    _case("grid: YAML nested 200 deep", _grid("description", "[" * 200 + "]" * 200), "grid.yaml",
          f"nested deeper than {MAX_YAML_DEPTH} levels"),
    _case("grid: alias inside itself", _grid("description", "&a [1, *a]"), "grid.yaml",
          f"nested deeper than {MAX_YAML_DEPTH} levels"),
    _case("preset: 2 MiB file", _big_preset, "preset.yaml", "refused", "MiB"),
    # JSON 100,000 levels deep
    _case("LERF label: JSON 100,000 deep", _deep_label, "frame_00001.json", TOO_DEEP_JSON),
    _case("gsbench_scene.json: JSON 100,000 deep", _scene_file("gsbench_scene.json", DEEP_JSON),
          "gsbench_scene.json", TOO_DEEP_JSON),
    _case("collect: results.json 100,000 deep", _collect(lambda p: p.write_text(DEEP_JSON)), exit_code=0,
          check=_failed_row(TOO_DEEP_JSON)),
    _case("collect: results.json over the size budget", _collect(_huge_file), exit_code=0,
          check=_failed_row("refused")),
    _case("collect: results.json not JSON", _collect(lambda p: p.write_text('{"run_id": ')), exit_code=0,
          check=_failed_row("corrupt or truncated JSON")),
    # list-valued config keys: length, element type and range
    _case("--set train.background=[1,2]", _set("train.background=[1,2]"), "train.background", "a list of 3 numbers"),
    _case("--set train.background=[a,b,c]", _set("train.background=[a,b,c]"), "train.background[0]",
          "must be a number"),
    _case("--set train.background=[]", _set("train.background=[]"), "train.background", "a list of 3 numbers"),
    _case("--set train.background=[1e9,-5,0]", _set("train.background=[1e9,-5,0]"), "train.background[0]",
          "in [0, 1]"),
    _case("--set semantic.autoencoder.hidden=[64,0]", _set("semantic.autoencoder.hidden=[64,0]"),
          "semantic.autoencoder.hidden[1]", "in [1, 8192]"),
    _case("--set priors.masks.model_overrides=[1]", _set("priors.masks.model_overrides=[1]"),
          "priors.masks.model_overrides[0]", "must be a str"),
    # a run folder's config.json
    _case("run config.json: null", _run_config(lambda cfg: None), "config.json", "must be a JSON object, got null"),
    _case("run config.json: a list", _run_config(lambda cfg: [cfg]), "config.json",
          "must be a JSON object, got list"),
    _case("run config.json: no scene", _run_config(lambda cfg: {k: v for k, v in cfg.items() if k != "scene"}),
          "config.json", "no scene path"),
    _case("run config.json: another method than its model", _run_config(_other_method, "gaussiands"),
          "config.json", "'vanilla'", "'gaussiands'"),
    # a run's identity: config.json must still give the run id it was trained under
    _case("run config.json: seed edited after training", _run_config(_edited("seed", 7)), "config.json",
          "does not give the run's id"),
    _case("run config.json: gaussiands.lambdas.sem edited after training",
          _run_config(_edited("gaussiands.lambdas.sem", 0.5), "gaussiands"), "config.json",
          "does not give the run's id"),
    _case("run config.json: scene fingerprint edited", _run_config(_edited("scene.fingerprint", "0" * 16)),
          "config.json", "does not give the run's id"),
    _case("run config.json: no run_id", _run_config(_without("run_id")), "config.json", "no run_id"),
    _case("eval of a run interrupted by SIGTERM", _interrupted_run, "run", "not finished", "'interrupted'"),
    # CLI input: an unbounded value is never echoed whole
    _case("--set with a 10,000-character key", _set("x" * 10_000 + "=1"), "xxx...xxx"),
    _case("--set with a 10,000-character value", _set("train.background=" + "y" * 10_000), "train.background",
          "yyy...yyy"),
]
