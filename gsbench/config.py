"""Config tree: default.yaml <- preset <- overrides, and the run id.

    cfg = load_config("gaussiands", "cpu-small", ["train.iterations=300", "backend=torch"])
    rid = run_id(cfg, scene_fingerprint(path))
    # the per-scene resolver is gsbench.methods.registry.resolve_for_scene (the methods floor)

This module is the one path by which a value enters a config: `gsbench train --set`, `gsbench
ablate --set`, presets and grid files (base.set, axes, sweeps, extra cells) all go through
`parse_overrides` (strings or mappings -> {dotted key: value}) and `check_value` / `apply_overrides`
(key known, type as in default.yaml or the method's spec, range or choices as in gsbench/config_keys.py
or the spec's rules). Values are read by one YAML reader (`load_yaml`, gsbench/yaml_reader.py), which
reads `1e-4` as a number and refuses a text over its size, node or depth budget.
Unknown keys are an error with close-match suggestions (a typo must not silently do nothing).
A preset is a shipped name (gsbench/configs/<name>.yaml) or a path to a YAML file.
"""
from __future__ import annotations

import copy
import difflib
import functools
import hashlib
import json
from pathlib import Path
from typing import Any, Iterable, Mapping, Optional

from gsbench.config_keys import FREE_MAPPINGS, METHODS, RULES, Rule
from gsbench.errors import InputError
from gsbench.method_table import SHARED_SECTIONS, get_spec, method_rules, moved_keys, section_defaults
from gsbench.yaml_reader import load_yaml, load_yaml_file, short_repr, short_text

CONFIG_DIR = Path(__file__).parent / "configs"
# keys that do not change what a run computes (where files go, how often it logs)
# keys that change where things are kept, not the results: left out of the run id (a run trained with
# train.data_on=device resumes with host, and the other way round)
NON_RESULT_KEYS = (("priors", "cache_dir"), ("train", "data_on"))
# keys added after run folders were stored: left out of the hash while they hold their null default,
# so the run ids (and config keys) of configs that do not set them stay what they were
NULL_DEFAULT_KEYS = (("train", "views"), ("gaussiands", "sem_geometry"))
# settings whose value names a rule the scene decides (`auto`): the config keeps the rule, and its `resolved`
# section ({dotted key: concrete value}, written where the config first meets its scene) gives what the rule
# chose there. The id hashes the concrete value, so `auto` on a synthetic scene is the same run as `gt`.
SCENE_RESOLVED_KEYS = ("priors.depth.provider",)
_NO_DEFAULT = object()


def _read_yaml(path: Path) -> dict:
    data = load_yaml_file(path)
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise InputError(f"{path}: a config file must be a mapping, got {type(data).__name__}")
    return data


def default_tree() -> dict:
    """The full default tree; its leaves are the keys (and their types) every config is checked against:
    default.yaml plus the own section of every registered method that brings one (a plugin's spec
    `defaults`; a section default.yaml already has cannot be redefined)."""
    tree = _read_yaml(CONFIG_DIR / "default.yaml")
    for section, defaults in section_defaults().items():
        if section in tree:
            raise InputError(f"a method's config section {section!r} is already a section of default.yaml")
        tree[section] = defaults
    return tree


def flatten(tree: Mapping, prefix: str = "") -> dict[str, Any]:
    """Leaves of a nested mapping as {dotted.key: value}; keys may already be dotted. Empty mappings
    and the free-form mappings of FREE_MAPPINGS are leaves."""
    out: dict[str, Any] = {}
    for k, v in tree.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping) and v and key not in FREE_MAPPINGS:
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out


def get_dotted(tree: Mapping, key: str) -> Any:
    """tree["a"]["b"] for "a.b"; KeyError when a part is missing."""
    node: Any = tree
    for part in key.split("."):
        if not isinstance(node, Mapping) or part not in node:
            raise KeyError(key)
        node = node[part]
    return node


def set_dotted(tree: dict, key: str, value: Any) -> None:
    parts = key.split(".")
    node = tree
    for part in parts[:-1]:
        node = node.setdefault(part, {})
    node[parts[-1]] = value


def parse_overrides(overrides: Mapping | Iterable[str] | None, where: str = "--set") -> dict[str, Any]:
    """["a.b=1", ...] (values read as YAML) or a mapping (dotted or nested keys) -> {dotted key: value}.

    Only the syntax is checked here; `apply_overrides` checks keys and values."""
    if not overrides:
        return {}
    if isinstance(overrides, Mapping):
        return flatten(overrides)
    if isinstance(overrides, str):
        overrides = [overrides]
    out: dict[str, Any] = {}
    for item in overrides:
        if not isinstance(item, str) or "=" not in item:
            raise InputError(f"{where} {short_repr(item)}: expected key=value (e.g. train.iterations=300)")
        k, v = item.split("=", 1)
        key = k.strip()
        if not key or any(not p for p in key.split(".")):
            raise InputError(f"{where} {short_repr(item)}: empty key")
        out[key] = load_yaml(v, f"{where} {short_text(key, 80)}") if v.strip() else None
    return out


def set_args(groups: Iterable[Iterable[str]] | None) -> list[str]:
    """The `--set` items of argparse's append+nargs form ([["a=1", "b=2"], ["c=3"]]) as one list, so
    `--set a=1 b=2` and `--set a=1 --set b=2` mean the same in every command."""
    return [item for group in (groups or []) for item in ([group] if isinstance(group, str) else group)]


def _unknown_key(key: str, leaves: Mapping[str, Any], where: str) -> InputError:
    if upgrade_key(key) != key and upgrade_key(key) in leaves:
        return InputError(f"{where}: config key {short_repr(key)} has moved: it is {upgrade_key(key)} now")
    section = [k for k in leaves if k.startswith(key + ".")]
    if section:
        return InputError(f"{where}: unknown config key {short_repr(key)} (a section; set one of its keys, "
                          f"e.g. {section[0]})")
    close = difflib.get_close_matches(key, list(leaves), n=3, cutoff=0.5) if len(key) <= 200 else []
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    return InputError(f"{where}: unknown config key {short_repr(key)} "
                      f"(not in gsbench/configs/default.yaml nor a method's section){hint}")


_KINDS = ((bool, "bool"), (int, "int"), (float, "float"), (str, "str"), (list, "list"), (dict, "dict"))  # bool first


def _kind(default: Any, rule: Optional[Rule]) -> Optional[str]:
    """The type a key takes: that of its default, or the rule's `kind` where the default is null."""
    for t, name in _KINDS:
        if isinstance(default, t):
            return name
    return rule.kind if rule is not None else None


def check_value(key: str, value: Any, leaves: Mapping[str, Any], where: str) -> Any:
    """The value `key` takes from `value`, or an InputError naming the key and what it accepts.

    Type from the default (a bool only from true/false, a number only from a number; a whole float
    such as 3e4 becomes an int for an integer key), then range or choices; a list's length, then each
    element by the rule's `item`."""
    default = leaves.get(key, _NO_DEFAULT)
    if default is _NO_DEFAULT:
        raise _unknown_key(key, leaves, where)
    rule = RULES.get(key) or method_rules().get(key)
    return _checked(key, value, _kind(default, rule), rule, default, where)


def _checked(key: str, value: Any, kind: Optional[str], rule: Optional[Rule], default: Any, where: str) -> Any:
    """check_value's work for a key or a list element (`default` _NO_DEFAULT: an element)."""
    given = value
    if value is None:
        if default is None or (rule is not None and rule.nullable):
            return None
        was = "" if default is _NO_DEFAULT else f" (default {short_repr(default)})"
        raise InputError(f"{where}: {key} cannot be null{was}")
    if kind == "bool" and not isinstance(value, bool):
        raise InputError(f"{where}: {key} must be true/false, got {short_repr(value)}")
    if kind in ("int", "float"):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            was = "" if default is _NO_DEFAULT else f" (default {short_repr(default)})"
            raise InputError(f"{where}: {key} must be a number{was}, got {short_repr(value)}")
        if kind == "int" or (rule is not None and rule.integer):
            if isinstance(value, float) and not value.is_integer():
                raise InputError(f"{where}: {key} must be a whole number, got {short_repr(value)}")
            value = int(value)
        else:
            value = float(value)
    expected = {"str": str, "list": list, "dict": dict}.get(kind or "")
    if expected is not None and not isinstance(value, expected):
        raise InputError(f"{where}: {key} must be a {'mapping' if kind == 'dict' else kind}, got {short_repr(value)}")
    if rule is not None and not rule.admits(value):
        raise InputError(f"{where}: {key}={short_repr(given)} is out of range: must be {rule.describe()}")
    if rule is not None and rule.item is not None and isinstance(value, list):
        value = [_checked(f"{key}[{i}]", v, rule.item.kind, rule.item, _NO_DEFAULT, where) for i, v in enumerate(value)]
    return copy.deepcopy(value)


def check_key(key: str, value: Any, where: str = "config") -> Any:
    """`check_value` against default.yaml: for code that takes a plain config dict (e.g. the priors
    pipeline called directly) and must hold it to the same rules as a loaded config."""
    return check_value(key, value, _default_leaves(), where)


def setting(config: Mapping, key: str) -> Any:
    """The config's value of a dotted key, else default.yaml's (a config written before the key existed,
    e.g. an older run folder's config.json): the one place a default is read, so no call site restates
    it. An unknown key is a KeyError (a programming error, not bad input)."""
    try:
        return get_dotted(config, key)
    except KeyError:
        return copy.deepcopy(get_dotted(_default_tree(), key))


@functools.lru_cache(maxsize=1)
def _default_tree() -> dict:
    return default_tree()


@functools.lru_cache(maxsize=1)
def _default_leaves() -> dict[str, Any]:
    """default.yaml's leaves, read once (check_value only reads them)."""
    return flatten(default_tree())


def apply_overrides(tree: dict, overrides: Mapping[str, Any], where: str = "--set",
                    leaves: Optional[Mapping[str, Any]] = None) -> dict:
    """Check each {dotted key: value} against default.yaml and the rules, then set it in `tree`."""
    leaves = flatten(default_tree()) if leaves is None else leaves
    for key, value in overrides.items():
        set_dotted(tree, key, check_value(key, value, leaves, where))
    return tree


def shipped_presets() -> list[str]:
    """The names of the presets gsbench ships (gsbench/configs/*.yaml but default.yaml), sorted: the one
    list, read from the folder, so a new preset file is everywhere a preset is listed."""
    return sorted(x.stem for x in CONFIG_DIR.glob("*.yaml") if x.stem != "default")


def preset_path(preset: str | Path) -> Path:
    """A shipped preset name or a path to a YAML file."""
    p = Path(preset)
    if p.suffix in (".yaml", ".yml"):
        if p.is_file():
            return p
        raise InputError(f"preset {str(preset)!r}: file not found")
    q = CONFIG_DIR / f"{preset}.yaml"
    if not q.exists():
        raise InputError(f"unknown preset {str(preset)!r} (no {q}); presets: {', '.join(shipped_presets())} "
                         "or a .yaml path")
    return q


def load_tree(preset: str | Path | None = None, overrides: Mapping | Iterable[str] | None = None,
              where: str = "--set") -> dict:
    """default.yaml <- preset <- overrides, every value checked (no method bookkeeping)."""
    tree = default_tree()
    leaves = flatten(tree)
    if preset:
        p = preset_path(preset)
        apply_overrides(tree, parse_overrides(_read_yaml(p), str(p)), str(p), leaves)
    apply_overrides(tree, parse_overrides(overrides, where), where, leaves)
    return tree


def load_config(method: str, preset: str | Path | None = None,
                overrides: Mapping | Iterable[str] | None = None) -> dict:
    """default.yaml <- preset <- overrides; `method` sets the `method` key (an override cannot change it)."""
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    flat = parse_overrides(overrides)
    if flat.get("method", method) != method:
        raise InputError(f"--set method={flat['method']} contradicts --method {method}")
    cfg = load_tree(preset, flat)
    cfg["method"] = method
    validate(cfg)
    return cfg


def validate(cfg: Mapping) -> None:
    """Check every key of a whole config tree (one written by hand or read back from config.json)."""
    leaves = flatten(default_tree())
    for key, value in flatten({k: v for k, v in cfg.items() if k in leaves or
                               any(x.startswith(k + ".") for x in leaves)}).items():
        check_value(key, value, leaves, "config")


def run_config(data: Any, path: str | Path) -> dict:
    """A run folder's config.json as read (`data`), checked for what loading the run needs: a mapping
    naming a known method and the scene's path, whose sections are mappings. Not every key is checked
    again: a run keeps the config it was trained with. Anything else is an InputError naming `path`."""
    if not isinstance(data, dict):
        kind = "null" if data is None else type(data).__name__
        raise InputError(f"{path}: a run's config must be a JSON object, got {kind}")
    method = data.get("method")
    if not isinstance(method, str) or method not in METHODS:
        raise InputError(f"{path}: method {short_repr(method)} is not a known method ({', '.join(METHODS)})")
    scene = data.get("scene")
    if not isinstance(scene, dict) or not isinstance(scene.get("path"), str):
        raise InputError(f"{path}: no scene path (a run's config holds the scene it was trained on as scene.path)")
    sections = [k for k, v in _default_tree().items() if isinstance(v, dict) and not isinstance(data.get(k, {}), dict)]
    if sections:
        raise InputError(f"{path}: section {sections[0]!r} must be a mapping")
    return upgrade_config(data)


def upgrade_key(key: str) -> str:
    """A dotted key (or dropped part) that a method moved (MethodSpec.moved), in today's layout; any other
    key as it is."""
    for old, new in moved_keys().items():
        if key == old or key.startswith(old + "."):
            return new + key[len(old):]
    return key


def upgrade_config(cfg: Any) -> Any:
    """A config written before a method moved some of its keys (MethodSpec.moved: e.g. d and the
    autoencoder, once GaussianDS's, now the shared `semantic` section) in today's layout, as a copy; any
    other value as it is. Old run folders and published cells stay readable; their run ids are the old
    layout's (docs/config.md, "Layouts")."""
    moved = [(old, new) for old, new in moved_keys().items() if _has_key(cfg, old)]
    if not moved:
        return cfg
    c = copy.deepcopy(cfg)
    for old, new in moved:
        *parents, leaf = old.split(".")
        set_dotted(c, new, get_dotted(c, ".".join(parents)).pop(leaf) if parents else c.pop(leaf))
    for part in ("dropped", "grid"):       # {dotted part or axis key: ...}
        if isinstance(c.get(part), dict):
            c[part] = {upgrade_key(str(k)): v for k, v in c[part].items()}
    for key, default in _default_leaves().items():
        # a key added since, with a null default (the behaviour before it existed): stated, as today's configs do
        if default is None and not _has_key(c, key) and isinstance(c.get(key.split(".")[0]), dict):
            set_dotted(c, key, None)
    return c


def _has_key(cfg: Any, key: str) -> bool:
    try:
        get_dotted(cfg, key)
        return True
    except KeyError:
        return False


def settled_value(cfg: Mapping, key: str) -> Optional[str]:
    """What the scene-decided rule at `key` (SCENE_RESOLVED_KEYS) chose, as the config's `resolved`
    section records it; None when it records no name there."""
    settled = cfg.get("resolved") if isinstance(cfg.get("resolved"), dict) else {}
    value = settled.get(key)
    return value if isinstance(value, str) else None


def canonical(cfg: dict) -> dict:
    """The config as far as it decides what a run computes: without the keys that only say where things
    are kept (NON_RESULT_KEYS), without the NULL_DEFAULT_KEYS left null, without bookkeeping (dropped,
    resolved, scene, run_id), without another method's own section and without the shared sections its
    method does not read. The one form both hashes below read."""
    c = copy.deepcopy(cfg)
    for key in SCENE_RESOLVED_KEYS:
        chosen = settled_value(c, key)
        if chosen is not None and _has_key(c, key):
            set_dotted(c, key, chosen)
    for path in NON_RESULT_KEYS:
        d = c
        for p in path[:-1]:
            d = d.get(p, {})
        if isinstance(d, dict):
            d.pop(path[-1], None)
    for *section, leaf in NULL_DEFAULT_KEYS:
        d = c
        for p in section:
            d = d.get(p, {})
        if isinstance(d, dict) and leaf in d and d[leaf] is None:
            del d[leaf]
    for k in ("dropped", "resolved", "scene", "run_id"):
        c.pop(k, None)
    # another method's own section (a plugin's) does not change this run: an installed plugin leaves
    # the run ids of every other method as they were
    spec = get_spec(c["method"]) if c.get("method") in METHODS else None
    for section in section_defaults():
        if spec is None or section != spec.section:
            c.pop(section, None)
    for section in SHARED_SECTIONS:
        if spec is None or section not in spec.shared:
            c.pop(section, None)
    return c


def run_id(config: dict, scene_fingerprint: str) -> str:
    """The run's identity: hash of the canonical config (seed included) and the scene fingerprint, 16
    hex digits. A grid names and resumes its cells by it."""
    text = json.dumps({"config": canonical(config), "scene": scene_fingerprint}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def config_key(config: Optional[dict]) -> str:
    """The setting a run belongs to: hash of the canonical config without its seed, 16 hex digits, so the
    seeds of one setting share it (collect's `config_key` column). No config: the hash of {}."""
    c = canonical(config) if config else {}
    c.pop("seed", None)
    return hashlib.sha256(json.dumps(c, sort_keys=True, default=str).encode("utf-8")).hexdigest()[:16]


__all__ = [
    "load_config",
    "load_tree",
    "run_id",
    "setting",
    "config_key",
    "canonical",
    "settled_value",
    "upgrade_config",
    "upgrade_key",
    "parse_overrides",
    "apply_overrides",
    "check_value",
    "load_yaml",
    "set_args",
    "validate",
    "run_config",
    "load_yaml_file",
    "short_repr",
    "preset_path",
    "shipped_presets",
    "default_tree",
    "flatten",
    "get_dotted",
    "set_dotted",
    "METHODS",
]
