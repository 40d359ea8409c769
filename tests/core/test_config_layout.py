"""Each method owns its settings: its section's defaults and rules come from its spec, the shared
`semantic` section leaves the run id of a method that does not read it, no ground-floor module names a
method's keys, and a config of the older layout (d, the autoencoder and L_sem's switch in `gaussiands`)
is read in today's layout, while setting a moved key says where it went."""
from __future__ import annotations

import copy
import re
from pathlib import Path

import pytest

from gsbench.config import canonical, load_config, run_config, run_id, upgrade_config, upgrade_key
from gsbench.errors import InputError
from gsbench.method_table import METHODS, SHARED_SECTIONS, get_spec

ROOT = Path(__file__).resolve().parents[2]


def test_a_method_section_takes_its_specs_defaults_and_rules():
    cfg = load_config("grouping")
    assert cfg["grouping"]["identity_dim"] == get_spec("grouping").defaults["identity_dim"]
    with pytest.raises(InputError, match=r"grouping.removal_threshold=2 is out of range: must be in \[0, 1\]"):
        load_config("grouping", None, ["grouping.removal_threshold=2"])
    with pytest.raises(InputError, match="gaussiands.depth_formulation='bogus' is out of range: must be one of none"):
        load_config("gaussiands", None, ["gaussiands.depth_formulation=bogus"])


def test_a_shared_section_leaves_the_run_id_of_a_method_that_does_not_read_it():
    for method in METHODS:
        spec = get_spec(method)
        a, b = load_config(method), load_config(method, None, ["semantic.latent_dim=7"])
        same = run_id(a, "scene") == run_id(b, "scene")
        assert same == ("semantic" not in spec.shared), method
        assert set(canonical(a)) & set(SHARED_SECTIONS) == set(spec.shared)


def test_another_methods_section_leaves_the_run_id():
    a, b = load_config("vanilla"), load_config("vanilla", None, ["gaussiands.lambdas.tv=3"])
    assert run_id(a, "s") == run_id(b, "s")
    g1, g2 = load_config("gaussiands"), load_config("gaussiands", None, ["gaussiands.lambdas.tv=3"])
    assert run_id(g1, "s") != run_id(g2, "s")


def _layout1(cfg: dict) -> dict:
    """`cfg` as gsbench wrote it before the shared section (by hand, not by the code under test)."""
    old = copy.deepcopy(cfg)
    sem = old.pop("semantic")
    old["gaussiands"]["latent_dim"] = sem["latent_dim"]
    old["gaussiands"]["autoencoder"] = sem["autoencoder"]
    old["gaussiands"]["losses"]["sem"] = sem["loss"]
    del old["gaussiands"]["edges"]["size"]       # a key added later with a null default
    old["dropped"] = {"gaussiands.autoencoder": "unused"}
    old["grid"] = {"gaussiands.latent_dim": sem["latent_dim"], "seed": 0}
    return old


def test_a_layout1_config_reads_as_todays():
    new = load_config("gaussiands", None, ["semantic.latent_dim=8", "semantic.loss=false"])
    old = _layout1(new)
    up = upgrade_config(old)
    assert up["semantic"] == new["semantic"] and up["gaussiands"] == new["gaussiands"]
    assert up["dropped"] == {"semantic.autoencoder": "unused"}
    assert up["grid"] == {"semantic.latent_dim": 8, "seed": 0}
    assert old["gaussiands"]["latent_dim"] == 8                 # the caller's dict is left as it was
    assert upgrade_config(new) is new                         # today's layout: nothing to do
    assert upgrade_key("gaussiands.autoencoder.epochs") == "semantic.autoencoder.epochs"
    assert upgrade_key("gaussiands.lambdas.sem") == "gaussiands.lambdas.sem"


def test_a_run_folders_old_config_is_read_in_todays_layout(tmp_path):
    old = _layout1(load_config("gaussiands"))
    old["scene"] = {"path": str(tmp_path)}
    assert run_config(old, tmp_path / "config.json")["semantic"]["latent_dim"] == 3


def test_setting_a_moved_key_says_where_it_went():
    with pytest.raises(InputError, match="'gaussiands.latent_dim' has moved: it is semantic.latent_dim now"):
        load_config("gaussiands", None, ["gaussiands.latent_dim=8"])


def test_the_ground_floor_names_no_methods_keys():
    """default.yaml and the ground-floor modules name no key of a method's own section."""
    sections = [get_spec(m).section for m in METHODS if get_spec(m).section]
    pattern = re.compile(r"\b(" + "|".join(map(re.escape, sections)) + r")\.[a-z_]+")
    files = [ROOT / "gsbench/configs/default.yaml", ROOT / "gsbench/config.py", ROOT / "gsbench/config_keys.py",
             ROOT / "gsbench/method_table.py"]
    found = [f"{f.name}: {m.group(0)}" for f in files for m in pattern.finditer(f.read_text())]
    assert found == []
