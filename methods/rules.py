"""Rules the method specs share: can the scene feed a depth prior or semantics, and switching losses
off with a recorded reason. The specs beside each method (methods/*_spec.py) call these."""
from __future__ import annotations

from typing import Callable, Optional

from gsbench.config import setting

Drop = Callable[[str, str], None]


def switch_off(on: dict, keys: tuple[str, ...], section: str, why: str, drop: Drop) -> None:
    """Turn off the loss switches `keys` of `on` that are on, each recorded as dropped with `why`."""
    for k in keys:
        if on[k]:
            on[k] = False
            drop(f"{section}.{k}", why)


def depth_source(cfg: dict, scene) -> tuple[bool, str]:
    """Can the scene feed the configured depth provider? (ok, reason when not)."""
    prov = setting(cfg, "priors.depth.provider")
    if prov == "auto":
        from gsbench.priors.depth import auto_depth_provider  # lazy: start-up (listing methods loads no priors)
        prov, why = auto_depth_provider(setting(cfg, "priors.depth"), scene)
        if prov is None:
            return False, why
    if prov in (None, "none"):
        return False, "priors.depth.provider=none"
    if prov == "gt" and not scene.has_depth:
        hint = " (priors.depth.provider=auto or sfm builds one from its sparse points)" if scene.has_points else ""
        return False, f"priors.depth.provider=gt but the scene has no GT depth{hint}"
    if prov in ("sparse", "sfm") and not scene.has_points:
        return False, f"priors.depth.provider={prov} but the scene has no sparse points"
    return True, ""


def semantic_source(cfg: dict, scene) -> tuple[bool, str]:
    """Can the scene feed the configured mask and feature providers? (ok, reason when not).

    The reason names what the scene lacks: instance maps (only synthetic scenes have them), any
    labels at all, or labels on a view that is trained on."""
    from gsbench.datasets.splits import split_ids  # lazy: start-up (listing methods loads no priors)
    from gsbench.priors.labels import SOURCE_TEXT, label_source, labelled_views  # lazy: start-up (as above)
    m = setting(cfg, "priors.masks.provider")
    f = setting(cfg, "priors.features.provider")
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
            holdout = setting(cfg, "train.holdout")
            return False, (f"the scene's {SOURCE_TEXT[labels]} are on {len(lab)} views, none of them trained on "
                           f"(train.holdout={holdout}): no view to take semantic targets from")
    return True, ""


def resolve_semantics(cfg: dict, scene, drop: Drop, also: Optional[tuple[dict, str, tuple[str, ...]]] = None) -> None:
    """L_sem (`semantic.loss`) and the method's own semantic switches `also` = (switches, their section,
    keys) off when the scene cannot feed them; the semantic priors and the autoencoder dropped when none
    is on."""
    own, section, keys = also if also is not None else ({}, "", ())
    ok, why = semantic_source(cfg, scene)
    if not ok:
        switch_off(cfg["semantic"], ("loss",), "semantic", why, drop)
        switch_off(own, keys, section, why, drop)
    if not (setting(cfg, "semantic.loss") or any(own[k] for k in keys)):
        names = " and ".join(["semantic.loss", *(f"{section}.{k}" for k in keys)])
        reason = why if not ok else f"nothing uses it ({names} {'are' if keys else 'is'} off)"
        for part in ("priors.masks", "priors.features", "semantic.autoencoder", "semantic_channels"):
            drop(part, reason)
