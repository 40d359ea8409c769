"""The method registry's behaviour: per-scene resolution, the priors request and the built-in rules.

Which methods exist, and their specs, is the ground-floor table gsbench/method_table.py (re-exported
here). This module imports what a spec names: the Method class (only when the method runs, so
listing methods stays cheap), its resolver (what to switch off when the scene cannot feed it, with
reasons) and its `uses` rule. Everything that used to repeat this knowledge reads it from the table
or from here: CLI choices, the config's `method` check, the per-scene resolver, the priors request
that both `train_phases()` and a grid's shared-priors step build, and the report order (registration order).
"""
from __future__ import annotations

import copy
import importlib
from pathlib import Path
from typing import Any, Optional

from gsbench.camera import training_size
from gsbench.config import setting
from gsbench.datasets import load_scene
from gsbench.datasets.splits import split_ids
from gsbench.errors import InputError
from gsbench.method_table import METHODS, SHARED_SECTIONS, MethodSpec, get_spec, method_sort_key, register, unregister


def load_target(target: str) -> Any:
    """The object a spec names as "module:attribute" (its module imported now)."""
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


def get_method(name: str) -> type:
    """The Method class registered under `name` (imported now)."""
    spec = get_spec(name)
    klass = load_target(spec.target)
    if getattr(klass, "name", None) != spec.name:
        raise TypeError(f"{spec.target}.name is {getattr(klass, 'name', None)!r}, registered as {spec.name!r}")
    return klass


def uses(config: dict) -> dict:
    """What the (resolved) config feeds: {"depth_prior": bool, "semantics": bool}, as its method registered."""
    return load_target(get_spec(config["method"]).uses)(config)


def budget(config: dict) -> dict:
    """The training budget of a (resolved) config, by its method's rule: {"rgb_steps", "semantic_steps"}."""
    return load_target(get_spec(config["method"]).budget)(config)


# ---------------------------------------------------------------------------- per-scene resolution
def resolve_for_scene(config: dict, scene) -> tuple[dict, dict]:
    """Switch off every loss, prior and output the scene cannot feed or nothing uses; record why.

    Returns (resolved config, dropped {part: reason}); the resolved config also carries `dropped`.
    Resolving a resolved config again gives the same losses and priors.
    """
    cfg = copy.deepcopy(config)
    spec = get_spec(cfg["method"])
    if spec.section is not None and not isinstance(cfg.get(spec.section), dict):
        raise InputError(f"method {spec.name}: the config has no {spec.section!r} section")
    dropped: dict[str, str] = {}

    def drop(part: str, reason: str) -> None:
        dropped.setdefault(part, reason)

    load_target(spec.resolve)(cfg, scene, drop)
    for section in SHARED_SECTIONS:
        if section not in spec.shared:
            drop(section, f"method {spec.name} does not read it")
    cfg["dropped"] = dropped
    return cfg, dropped


# ---------------------------------------------------------------------------- priors request
def priors_request(config: dict, scene) -> Optional[dict]:
    """What the method will ask gsbench.priors for, or None when it needs no priors.

    `config` may be resolved or not (it is resolved for `scene` here); `scene` is a loaded scene or
    its folder. A grid groups cells by this dict; train_phases() computes its priors from the same dict
    (methods/base.py fit_priors), so equal requests hit the same cache entry.
    """
    req = build_priors_request(config, scene)
    if req is None or not (req["need_depth"] or req["need_sem"]):
        return None
    return req


def autoencoder_request(config: dict, priors_req: Optional[dict]) -> Optional[dict]:
    """The feature autoencoder's fit the cell will make from its priors (`priors_req`), or None. Methods that
    read the shared `semantic` section fit it on the priors' mask features when semantics are on
    (gsbench.train.semantic_targets); a grid makes each fit two or more cells share once, before them.
    Were this to ask for another fit than the cell's, the cell would miss the cache and fit its own."""
    if priors_req is None or not priors_req["need_sem"] or "semantic" not in get_spec(config["method"]).shared:
        return None
    return dict(priors_req, autoencoder=setting(config, "semantic.autoencoder"),
                latent_dim=int(setting(config, "semantic.latent_dim")))


def build_priors_request(config: dict, scene) -> Optional[dict]:
    """The request even when it asks for nothing (fit still orders the views); None without train views."""
    if isinstance(scene, (str, Path)):
        scene = load_scene(scene)
    cfg, _ = resolve_for_scene(config, scene)
    train_ids, _ = split_ids(scene, cfg)   # the views the method trains on (train.holdout)
    if not train_ids:
        return None
    spec = get_spec(cfg["method"])
    use = load_target(spec.uses)(cfg)
    w, h = training_size(scene.cameras[train_ids[0]], setting(cfg, "train.max_width"))
    return {"scene_path": str(scene.path), "priors": setting(cfg, "priors"), "view_ids": sorted(train_ids),
            "size": [w, h], "need_depth": bool(use["depth_prior"]), "need_sem": bool(use["semantics"]),
            "per_frame": bool(spec.per_frame_masks), "seed": int(setting(cfg, "seed"))}


__all__ = ["MethodSpec", "METHODS", "register", "unregister", "get_spec", "get_method", "method_sort_key", "uses",
           "budget", "load_target", "resolve_for_scene", "priors_request", "build_priors_request",
           "autoencoder_request"]
