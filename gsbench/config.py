"""Config tree: default.yaml <- preset <- overrides, the run id, and the per-scene resolver.

    cfg = load_config("gaussiands", "cpu-small", ["train.iterations=300", "backend=torch"])
    rid = run_id(cfg, scene_fingerprint(path))
    cfg, dropped = resolve_for_scene(cfg, scene)   # drops what the scene cannot feed or nothing uses

Override values are parsed as YAML (`1e-3`, `true`, `[1, 2]`, `null`). Unknown keys are an error
(a typo must not silently do nothing). Presets live in gsbench/configs/<name>.yaml or are a path.
"""
from __future__ import annotations

import copy
import re
import hashlib
import json
from pathlib import Path
from typing import Any, Mapping

import yaml

from gsbench.errors import InputError

CONFIG_DIR = Path(__file__).parent / "configs"
from gsbench.methods.registry import METHODS  # noqa: E402  (live: the registered method names)
# keys that do not change what a run computes (where files go, how often it logs)
NON_RESULT_KEYS = (("priors", "cache_dir"),)


def _read_yaml(path: Path) -> dict:
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: config file not found") from None
    except yaml.YAMLError as e:
        raise InputError(f"{path}: invalid YAML ({e})") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise InputError(f"{path}: a config file must be a mapping, got {type(data).__name__}")
    return data


def _merge(base: dict, over: Mapping, where: str, path: str = "") -> dict:
    for k, v in over.items():
        key = f"{path}{k}"
        if k not in base:
            raise InputError(f"{where}: unknown config key {key!r}")
        if isinstance(base[k], dict) and isinstance(v, Mapping):
            _merge(base[k], v, where, key + ".")
        elif (isinstance(base[k], (int, float)) and not isinstance(base[k], bool)
              and isinstance(v, (str, bool, list, Mapping))):     # a number (or null) is expected
            raise InputError(f"{where}: {key} must be a number (default {base[k]!r}), got {v!r}")
        else:
            base[k] = copy.deepcopy(v)
    return base


_FLOAT_RE = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def _number_or_value(v: Any) -> Any:
    """YAML 1.1 reads '1e-4' / '1e38' as strings; a command-line user means the number."""
    if isinstance(v, str) and _FLOAT_RE.match(v.strip()):
        return float(v)
    return v


def parse_overrides(overrides: Mapping | list[str] | None) -> dict:
    """["a.b=1", ...] or {"a.b": 1} -> nested dict (values parsed as YAML)."""
    if not overrides:
        return {}
    items: list[tuple[str, Any]] = []
    if isinstance(overrides, Mapping):
        items = list(overrides.items())
    else:
        for s in overrides:
            if "=" not in s:
                raise InputError(f"--set {s!r}: expected key=value (e.g. train.iterations=300)")
            k, v = s.split("=", 1)
            try:
                items.append((k.strip(), _number_or_value(yaml.safe_load(v))))
            except yaml.YAMLError as e:
                raise InputError(f"--set {s!r}: value is not valid YAML ({e})") from None
    out: dict = {}
    for k, v in items:
        parts = [p for p in str(k).split(".") if p]
        if not parts:
            raise InputError(f"--set: empty key in {k!r}")
        d = out
        for p in parts[:-1]:
            d = d.setdefault(p, {})
            if not isinstance(d, dict):
                raise InputError(f"--set: {k!r} conflicts with another override")
        d[parts[-1]] = v
    return out


def preset_path(preset: str) -> Path:
    p = Path(preset)
    if p.suffix in (".yaml", ".yml") and p.exists():
        return p
    q = CONFIG_DIR / f"{preset}.yaml"
    if not q.exists():
        names = sorted(x.stem for x in CONFIG_DIR.glob("*.yaml") if x.stem != "default")
        raise InputError(f"unknown preset {preset!r} (no {q}); presets: {', '.join(names)}")
    return q


def load_config(method: str, preset: str | None = None, overrides: Mapping | list[str] | None = None) -> dict:
    """default.yaml <- preset <- overrides; `method` sets the `method` key (an override cannot change it)."""
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    cfg = _read_yaml(CONFIG_DIR / "default.yaml")
    if preset:
        p = preset_path(preset)
        _merge(cfg, _read_yaml(p), str(p))
    _merge(cfg, parse_overrides(overrides), "--set")
    if cfg.get("method") not in (None, method) and overrides and "method" in parse_overrides(overrides):
        raise InputError(f"--set method={cfg['method']} contradicts --method {method}")
    cfg["method"] = method
    validate(cfg)
    return cfg


def validate(cfg: dict) -> None:
    """Checks of values that would otherwise fail deep inside training."""
    from gsbench.methods.losses import DEPTH_FORMULATIONS
    g = cfg["gaussiands"]
    if g["depth_formulation"] not in DEPTH_FORMULATIONS:
        raise InputError(f"gaussiands.depth_formulation={g['depth_formulation']!r}: choose one of {', '.join(DEPTH_FORMULATIONS)}")
    if not isinstance(g["latent_dim"], int) or g["latent_dim"] < 1:
        raise InputError(f"gaussiands.latent_dim={g['latent_dim']!r}: must be an integer >= 1")
    if cfg["query"]["mode"] not in ("encode", "decode"):
        raise InputError(f"query.mode={cfg['query']['mode']!r}: choose encode or decode")
    t = cfg["train"]
    if not isinstance(t["iterations"], int) or t["iterations"] < 0:
        raise InputError(f"train.iterations={t['iterations']!r}: must be an integer >= 0")
    if t["max_width"] is not None and (not isinstance(t["max_width"], int) or t["max_width"] < 1):
        raise InputError(f"train.max_width={t['max_width']!r}: must be null or an integer >= 1")
    if t["init"]["mode"] not in ("auto", "points", "random"):
        raise InputError(f"train.init.mode={t['init']['mode']!r}: choose auto, points or random")
    for k, v in g["lambdas"].items():
        if not isinstance(v, (int, float)) or v < 0:
            raise InputError(f"gaussiands.lambdas.{k}={v!r}: must be a number >= 0")


def _canonical(cfg: dict) -> dict:
    c = copy.deepcopy(cfg)
    for path in NON_RESULT_KEYS:
        d = c
        for p in path[:-1]:
            d = d.get(p, {})
        if isinstance(d, dict):
            d.pop(path[-1], None)
    for k in ("dropped", "resolved", "scene", "run_id"):
        c.pop(k, None)
    return c


def run_id(config: dict, scene_fingerprint: str) -> str:
    """Hash of the config (without paths/bookkeeping) and the scene fingerprint: 16 hex digits."""
    text = json.dumps({"config": _canonical(config), "scene": scene_fingerprint}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


# ---------------------------------------------------------------------------- per-scene resolution
def resolve_for_scene(config: dict, scene) -> tuple[dict, dict]:
    """Switch off what the scene cannot feed or nothing uses, as the config's method registered it
    (gsbench/methods/registry.py). Returns (resolved config, dropped {part: reason})."""
    from gsbench.methods.registry import resolve_for_scene as resolve
    return resolve(config, scene)


__all__ = ["load_config", "run_id", "resolve_for_scene", "parse_overrides", "validate", "METHODS"]
