"""Every structured input is bounded and checked (issue 39): YAML through gsbench.config.load_yaml (size,
nodes with aliases expanded, depth), JSON through gsbench.store.read_json (size, depth), list-valued
config keys by length, element type and range, and a run folder's config.json by its shape and its
model's method. The hostile:config battery runs the same inputs through the CLI; each of its cases is
run here too."""
from __future__ import annotations

import json
import logging
import time

import pytest

from gsbench import config, store
from gsbench.commands.hostile import run_hostile
from gsbench.commands.hostile.config import CASES, alias_bomb
from gsbench.config import load_config, load_yaml, load_yaml_file
from gsbench.config_keys import RULES
from gsbench.errors import InputError
from gsbench.grids import load_grid
from gsbench.store import json_depth, read_json, read_jsonl

# ------------------------------------------------------------------------------------ YAML


def test_a_billion_laughs_is_refused_at_once_without_echoing_it():
    t0 = time.perf_counter()
    with pytest.raises(InputError) as e:
        load_yaml(f"description: {alias_bomb(9, 9)}\n", "bomb.yaml")
    assert time.perf_counter() - t0 < 5.0       # it took 28 s and 2.8 GB before
    msg = str(e.value)
    assert msg.startswith("bomb.yaml: refused:") and "more than 50000 nodes" in msg and "lol" not in msg
    assert len(msg) < 200


def test_aliases_under_the_budget_are_read():
    data = load_yaml(f"x: {alias_bomb(4, 9)}\n")     # 9 + 81 + 729 + 6561 leaves, 7381 nodes in all
    assert len(data["x"]) == 4
    assert data["x"][0] == ["lol"] * 9
    assert data["x"][3][8][8][8] == ["lol"] * 9


def test_an_alias_inside_itself_is_refused():
    for text in ("&a [1, *a]", "x: &x {y: *x}"):
        with pytest.raises(InputError, match=r"^f.yaml: refused: YAML nested deeper than 64 levels"):
            load_yaml(text, "f.yaml")


@pytest.mark.parametrize("depth", [65, 200, 5000])
def test_deep_yaml_is_refused(depth):
    """200 is past gsbench's 64 levels; 5000 is past libyaml's own limit of 1000: the same line."""
    with pytest.raises(InputError, match=r"^g.yaml: refused: YAML nested deeper than 64 levels$"):
        load_yaml("[" * depth + "]" * depth, "g.yaml")


def test_yaml_64_levels_deep_is_read():
    data = load_yaml("[" * 64 + "1" + "]" * 64)
    for _ in range(64):
        assert isinstance(data, list) and len(data) == 1
        data = data[0]
    assert data == 1


def test_a_yaml_text_or_file_over_the_size_budget_is_refused(tmp_path):
    with pytest.raises(InputError, match=r"^s: refused: 1048577 characters of YAML, more than the 1 MiB"):
        load_yaml("#" * (1024 * 1024 + 1), "s")
    big = tmp_path / "big.yaml"
    with open(big, "wb") as f:        # sparse: refused from its size, never read
        f.truncate(50 * 1024 * 1024)
    with pytest.raises(InputError, match=r"big.yaml: refused: 52428800 bytes, more than the 1 MiB"):
        load_yaml_file(big)


def test_invalid_yaml_is_one_line_naming_the_place():
    with pytest.raises(InputError) as e:
        load_yaml("a: [1, 2\nb: {", "p.yaml")
    msg = str(e.value)
    assert msg.startswith("p.yaml: invalid YAML (") and "\n" not in msg and "line" in msg


def test_alias_bombs_in_a_grid_a_preset_and_set(tmp_path):
    grid = tmp_path / "grid.yaml"
    grid.write_text(f"study: tiny-test\nseeds: {alias_bomb()}\nbase: {{method: vanilla}}\nscenes: [tabletop-small]\n")
    with pytest.raises(InputError, match=rf"^{grid}: refused: YAML of more than 50000 nodes"):
        load_grid(grid)
    preset = tmp_path / "preset.yaml"
    preset.write_text(f"train.background: {alias_bomb()}\n")
    with pytest.raises(InputError, match=rf"^{preset}: refused: YAML of more than 50000 nodes"):
        load_config("vanilla", preset)
    with pytest.raises(InputError, match=r"^--set train.background: refused: YAML of more than 50000 nodes"):
        load_config("vanilla", None, [f"train.background={alias_bomb()}"])


def test_grid_seeds_under_the_budget_are_not_echoed_whole(tmp_path):
    grid = tmp_path / "grid.yaml"
    grid.write_text(f"study: tiny-test\nseeds: {alias_bomb(4)}\nbase: {{method: vanilla}}\nscenes: [tabletop-small]\n")
    with pytest.raises(InputError) as e:
        load_grid(grid)
    assert "seeds must be integers, got [['lol'" in str(e.value) and len(str(e.value)) < 120 + len(str(grid)) + 40


# ------------------------------------------------------------------------------------ JSON


def test_json_depth_counts_brackets_outside_strings():
    assert json_depth("1") == 0
    assert json_depth('{"a": [1, {"b": []}]}') == 4
    assert json_depth('{"a": "[[[[{{{{", "b": "\\"[[[", "c": "\\\\"}') == 1
    assert json_depth('["\\\\\\"[[", [[]]]') == 3


def test_deep_json_is_refused_naming_the_file(tmp_path):
    p = tmp_path / "deep.json"
    p.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(InputError, match=rf"^{p}: refused: JSON nested deeper than 64 levels$"):
        read_json(p)
    p.write_text("[" * 65 + "]" * 65)
    with pytest.raises(InputError, match="nested deeper than 64 levels"):
        read_json(p)
    p.write_text("[" * 64 + "]" * 64 + "\n")
    data = read_json(p)
    for _ in range(63):
        data = data[0]
    assert data == []
    p.write_text(json.dumps({"a": "[" * 1000}))
    assert read_json(p) == {"a": "[" * 1000}


def test_a_json_file_over_the_size_budget_is_refused_unread(tmp_path, monkeypatch):
    p = tmp_path / "big.json"
    with open(p, "wb") as f:
        f.truncate(64 * 1024 * 1024 + 1)
    with pytest.raises(InputError, match=rf"^{p}: refused: 67108865 bytes, more than the 64 MiB"):
        read_json(p)
    monkeypatch.setattr(store, "MAX_JSON_BYTES", 10)
    with pytest.raises(InputError, match=r"^x: refused: 11 characters of JSON"):
        store.parse_json('{"a": "12"}', "x")


def test_read_jsonl_skips_a_deep_line_with_a_warning(tmp_path, caplog):
    p = tmp_path / "log.jsonl"
    p.write_text('{"step": 1}\n' + "[" * 200 + "]" * 200 + '\n{"step": 2}\n{"step": ')
    with caplog.at_level(logging.WARNING, logger="gsbench.store"):
        assert read_jsonl(p) == [{"step": 1}, {"step": 2}]
    assert f"{p} line 2: refused: JSON nested deeper than 64 levels" in caplog.text


# ------------------------------------------------------------------------------------ list-valued keys


def test_every_list_valued_key_has_a_length_and_element_rule():
    lists = [k for k, v in config.flatten(config.default_tree()).items() if isinstance(v, list)]
    assert {"train.background", "semantic.autoencoder.hidden", "priors.masks.model_overrides"} <= set(lists)
    for key in lists:
        rule = RULES.get(key)
        assert rule is not None and rule.length is not None and rule.item is not None and rule.item.kind, key


@pytest.mark.parametrize("item, message", [
    ("train.background=[1,2]", "train.background=[1, 2] is out of range: must be a list of 3 numbers, each in [0, 1]"),
    ("train.background=[a,b,c]", "train.background[0] must be a number, got 'a'"),
    ("train.background=[]", "train.background=[] is out of range: must be a list of 3 numbers"),
    ("train.background=[1e9,-5,0]", "train.background[0]=1000000000.0 is out of range: must be in [0, 1]"),
    ("train.background=[0,null,0]", "train.background[1] cannot be null"),
    ("train.background=[true,0,0]", "train.background[0] must be a number, got True"),
    ("semantic.autoencoder.hidden=[64, 2.5]", "semantic.autoencoder.hidden[1] must be a whole number, got 2.5"),
    ("semantic.autoencoder.hidden=[64, 0]", "hidden[1]=0 is out of range: must be in [1, 8192]"),
    ("semantic.autoencoder.hidden=[" + ",".join(["8"] * 17) + "]", "must be a list of 0 to 16 whole numbers"),
    ("priors.masks.model_overrides=[a, 1]", "priors.masks.model_overrides[1] must be a str, got 1"),
])
def test_list_values_are_checked(item, message):
    with pytest.raises(InputError) as e:
        load_config("gaussiands", None, [item])
    assert str(e.value).startswith("--set: ") and message in str(e.value) and len(str(e.value)) < 200


def test_good_list_values_are_taken():
    cfg = load_config("gaussiands", None, ["train.background=[1, 0, 0.5]", "semantic.autoencoder.hidden=[64.0, 32]",
                                           "priors.masks.model_overrides=['++model.x=1']"])
    assert cfg["train"]["background"] == [1.0, 0.0, 0.5]
    assert cfg["semantic"]["autoencoder"]["hidden"] == [64, 32]
    assert isinstance(cfg["semantic"]["autoencoder"]["hidden"][0], int)
    assert cfg["priors"]["masks"]["model_overrides"] == ["++model.x=1"]
    empty = load_config("gaussiands", None, ["semantic.autoencoder.hidden=[]"])
    assert empty["semantic"]["autoencoder"]["hidden"] == []


def test_a_long_value_is_not_echoed():
    with pytest.raises(InputError) as e:
        load_config("vanilla", None, ["train.iterations=[" + ",".join(["123456789"] * 5000) + "]"])
    assert "train.iterations must be a number" in str(e.value) and len(str(e.value)) < 250


# ------------------------------------------------------------------------------------ run config.json


@pytest.mark.parametrize("data, message", [
    (None, "a run's config must be a JSON object, got null"),
    ([1], "a run's config must be a JSON object, got list"),
    ({"scene": {"path": "/s"}}, "method None is not a known method"),
    ({"method": "nope", "scene": {"path": "/s"}}, "method 'nope' is not a known method"),
    ({"method": "vanilla"}, "no scene path"),
    ({"method": "vanilla", "scene": {"path": "/s"}, "train": [1]}, "section 'train' must be a mapping"),
])
def test_a_run_config_must_be_an_object_with_what_loading_needs(data, message):
    with pytest.raises(InputError, match=r"^run/config.json: ") as e:
        config.run_config(data, "run/config.json")
    assert message in str(e.value)


def test_a_run_config_with_what_loading_needs_is_taken():
    data = {"method": "vanilla", "scene": {"path": "/s"}, "seed": 3}
    assert config.run_config(data, "c.json") is data


# ------------------------------------------------------------------------------------ the CLI battery


@pytest.mark.parametrize("case", CASES, ids=[h.name for h in CASES])
def test_hostile_config_case(case):
    """Each case through `gsbench` itself: the exit status, one short error line with the file and the
    limit, no traceback (collect: exit 0, a failed row naming the file, the good run's rows)."""
    res = run_hostile(case)
    assert res.passed, res.note
