"""The method registry's behaviour: per-scene resolution, the priors request and the built-in rules.

Which methods exist, and their specs, is the ground-floor table gsbench/method_table.py (re-exported
here). This module imports what a spec names: the Method class (only when the method runs, so
listing methods stays cheap), its resolver (what to switch off when the scene cannot feed it, with
reasons) and its `uses` rule. Everything that used to repeat this knowledge reads it from the table
or from here: CLI choices, the config's `method` check, the per-scene resolver, the priors request
that both `fit()` and a grid's shared-priors step build, and the report order (registration order).
"""
from __future__ import annotations

import copy
import importlib
from pathlib import Path
from typing import Any, Callable, Optional

from gsbench.datasets import load_scene
from gsbench.datasets.splits import split_ids
from gsbench.errors import InputError
from gsbench.method_table import METHODS, MethodSpec, get_spec, method_sort_key, register, unregister
from gsbench.priors.labels import SOURCE_TEXT, label_source, labelled_views
from gsbench.scene import training_size

Drop = Callable[[str, str], None]


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
    cfg["dropped"] = dropped
    return cfg, dropped


def depth_source(cfg: dict, scene) -> tuple[bool, str]:
    """Can the scene feed the configured depth provider? (ok, reason when not)."""
    prov = cfg["priors"]["depth"]["provider"]
    if prov in (None, "none"):
        return False, "priors.depth.provider=none"
    if prov == "gt" and not scene.has_depth:
        return False, "priors.depth.provider=gt but the scene has no GT depth"
    if prov == "sparse" and not scene.has_points:
        return False, "priors.depth.provider=sparse but the scene has no sparse points"
    return True, ""


def semantic_source(cfg: dict, scene) -> tuple[bool, str]:
    """Can the scene feed the configured mask and feature providers? (ok, reason when not).

    The reason names what the scene lacks: instance maps (only synthetic scenes have them), any
    labels at all, or labels on a view that is trained on."""
    m = cfg["priors"]["masks"]["provider"]
    f = cfg["priors"]["features"]["provider"]
    labels = label_source(scene)
    none = "(no semantics in the scene)"
    if m == "simulated" and not scene.has_instances:
        tail = f"; its {SOURCE_TEXT[labels]} can feed priors.masks.provider=gt" if labels else f" {none}"
        return False, ("priors.masks.provider=simulated needs GT instance maps (synthetic scenes) and the scene "
                       f"has none{tail}")
    if m == "gt" and not scene.has_instances and labels is None:
        return False, ("priors.masks.provider=gt needs GT instance maps, 3D-OVS class masks or LERF-OVS labels, "
                       f"and the scene has none of them {none}")
    if f == "text-aligned" and not (labels or (scene.has_instances and scene.instance_classes and scene.class_names)):
        return False, ("priors.features.provider=text-aligned needs GT classes (3D-OVS class masks, LERF-OVS labels "
                       f"or a synthetic scene's instance classes) and the scene has none {none}")
    if labels and not scene.has_instances and (m == "gt" or f == "text-aligned"):
        train, _ = split_ids(scene, cfg)
        lab = labelled_views(scene)
        if not set(train) & set(lab):
            holdout = (cfg.get("train") or {}).get("holdout", "every-8")
            return False, (f"the scene's {SOURCE_TEXT[labels]} are on {len(lab)} views, none of them trained on "
                           f"(train.holdout={holdout}): no view to take semantic targets from")
    return True, ""


def resolve_semantics(cfg: dict, scene, drop: Drop) -> None:
    """Semantic losses off when the scene cannot feed them; semantic priors dropped when unused."""
    on = cfg["gaussiands"]["losses"]
    ok, why = semantic_source(cfg, scene)
    if not ok:
        _switch_off(on, ("sem", "ds"), "gaussiands.losses", why, drop)
    if not (on["sem"] or on["ds"]):
        reason = why if not ok else "nothing uses it (gaussiands.losses.sem and .ds are off)"
        for part in ("priors.masks", "priors.features", "gaussiands.autoencoder", "semantic_channels"):
            drop(part, reason)


# ---------------------------------------------------------------------------- priors request
def priors_request(config: dict, scene) -> Optional[dict]:
    """What the method will ask gsbench.priors for, or None when it needs no priors.

    `config` may be resolved or not (it is resolved for `scene` here); `scene` is a loaded scene or
    its folder. A grid groups cells by this dict; fit() computes its priors from the same dict
    (methods/common.py fit_priors), so equal requests hit the same cache entry.
    """
    req = build_priors_request(config, scene)
    if req is None or not (req["need_depth"] or req["need_sem"]):
        return None
    return req


def build_priors_request(config: dict, scene) -> Optional[dict]:
    """The request even when it asks for nothing (fit still orders the views); None without train views."""
    if isinstance(scene, (str, Path)):
        scene = load_scene(scene)
    cfg, _ = resolve_for_scene(config, scene)
    train_ids, _ = split_ids(scene, cfg)   # the views fit() trains on (train.holdout)
    if not train_ids:
        return None
    spec = get_spec(cfg["method"])
    use = load_target(spec.uses)(cfg)
    w, h = training_size(scene.cameras[train_ids[0]], cfg["train"].get("max_width"))
    return {"scene_path": str(scene.path), "priors": cfg["priors"], "view_ids": sorted(train_ids),
            "size": [w, h], "need_depth": bool(use["depth_prior"]), "need_sem": bool(use["semantics"]),
            "per_frame": bool(spec.per_frame_masks), "seed": int(cfg["seed"])}


# ---------------------------------------------------------------------------- the built-in methods
def resolve_vanilla(cfg: dict, scene, drop: Drop) -> None:
    on = cfg["gaussiands"]["losses"]
    for k in ("depth", "tv", "sem", "ds"):
        on[k] = False
    for part in ("priors.depth", "priors.masks", "priors.features", "gaussiands.autoencoder", "semantic_channels"):
        drop(part, "method vanilla is RGB only")


def uses_vanilla(cfg: dict) -> dict:
    return {"depth_prior": False, "semantics": False}


def resolve_twostage(cfg: dict, scene, drop: Drop) -> None:
    on = cfg["gaussiands"]["losses"]
    on["depth"] = on["tv"] = on["ds"] = False
    drop("priors.depth", "method twostage uses no depth prior (RGB, then semantics on frozen geometry)")
    for k in ("depth", "tv", "ds"):
        drop(f"gaussiands.losses.{k}", "method twostage: RGB + L_sem only")
    resolve_semantics(cfg, scene, drop)


def uses_twostage(cfg: dict) -> dict:
    return {"depth_prior": False, "semantics": bool(cfg["gaussiands"]["losses"]["sem"])}


def _switch_off(on: dict, keys: tuple[str, ...], section: str, why: str, drop: Drop) -> None:
    """Turn off the loss switches `keys` of `on` that are on, each recorded as dropped with `why`."""
    for k in keys:
        if on[k]:
            on[k] = False
            drop(f"{section}.{k}", why)


def resolve_gaussiands(cfg: dict, scene, drop: Drop) -> None:
    g = cfg["gaussiands"]
    on = g["losses"]
    if g["depth_formulation"] == "none" and on["depth"]:
        on["depth"] = False
        drop("gaussiands.losses.depth", "gaussiands.depth_formulation=none")
    ok, why = depth_source(cfg, scene)
    if not ok:
        _switch_off(on, ("depth", "ds"), "gaussiands.losses", f"no depth prior: {why}", drop)
        drop("priors.depth", why)
    elif not (on["depth"] or on["ds"]):
        drop("priors.depth", "nothing uses it (gaussiands.losses.depth and .ds are off)")
    resolve_semantics(cfg, scene, drop)


def uses_gaussiands(cfg: dict) -> dict:
    g = cfg["gaussiands"]
    on = g["losses"]
    depth_terms = bool(on["depth"] and g["depth_formulation"] != "none") or bool(on["ds"])
    return {"depth_prior": depth_terms, "semantics": bool(on["sem"] or on["ds"])}


def resolve_grouping(cfg: dict, scene, drop: Drop) -> None:
    on = cfg["grouping"]["losses"]
    drop("priors.depth", "method grouping uses no depth prior (RGB + identity classification)")
    drop("gaussiands.autoencoder", "method grouping has no autoencoder: queries go through the tracks' features")
    ok, why = semantic_source(cfg, scene)
    if not ok:
        _switch_off(on, ("identity", "reg3d"), "grouping.losses", why, drop)
    if on["reg3d"] and not on["identity"]:
        on["reg3d"] = False
        drop("grouping.losses.reg3d", "the 3D regulariser acts on the identity classes (grouping.losses.identity off)")
    if not on["identity"]:
        reason = why if not ok else "nothing uses it (grouping.losses.identity is off)"
        for part in ("priors.masks", "priors.features", "semantic_channels"):
            drop(part, reason)


def uses_grouping(cfg: dict) -> dict:
    return {"depth_prior": False, "semantics": bool(cfg["grouping"]["losses"]["identity"])}


__all__ = ["MethodSpec", "METHODS", "register", "unregister", "get_spec", "get_method", "method_sort_key", "uses",
           "load_target", "resolve_vanilla", "uses_vanilla", "resolve_twostage", "uses_twostage",
           "resolve_gaussiands", "uses_gaussiands", "resolve_grouping", "uses_grouping",
           "resolve_for_scene", "priors_request", "build_priors_request", "depth_source", "semantic_source",
           "resolve_semantics"]
