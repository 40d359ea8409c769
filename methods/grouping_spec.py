"""The spec of `grouping` (a Gaussian Grouping-style joint identity baseline): registration, what the
scene must feed, and its budget (methods/grouping.py is the method)."""
from __future__ import annotations

from gsbench.method_table import MethodSpec
from gsbench.methods.rules import Drop, semantic_source, switch_off


def resolve(cfg: dict, scene, drop: Drop) -> None:
    """No depth prior and no autoencoder; identity and 3D-regulariser losses as the scene allows."""
    on = cfg["grouping"]["losses"]
    drop("priors.depth", "method grouping uses no depth prior (RGB + identity classification)")
    drop("gaussiands.autoencoder", "method grouping has no autoencoder: queries go through the tracks' features")
    ok, why = semantic_source(cfg, scene)
    if not ok:
        switch_off(on, ("identity", "reg3d"), "grouping.losses", why, drop)
    if on["reg3d"] and not on["identity"]:
        on["reg3d"] = False
        drop("grouping.losses.reg3d", "the 3D regulariser acts on the identity classes (grouping.losses.identity off)")
    if not on["identity"]:
        reason = why if not ok else "nothing uses it (grouping.losses.identity is off)"
        for part in ("priors.masks", "priors.features", "semantic_channels"):
            drop(part, reason)


def uses(cfg: dict) -> dict:
    return {"depth_prior": False, "semantics": bool(cfg["grouping"]["losses"]["identity"])}


def budget(cfg: dict) -> dict:
    """Joint training: every step is also a semantic step when the identity loss is on."""
    steps = int(cfg["train"]["iterations"])
    sem = uses(cfg)["semantics"]
    return {"rgb_steps": steps, "semantic_steps": steps if sem else 0, "schedule": "joint" if sem else "none"}


SPEC = MethodSpec(name="grouping", target="gsbench.methods.grouping:GaussianGrouping",
                  label="Gaussian Grouping (style)", section="grouping", resolve=f"{__name__}:resolve",
                  uses=f"{__name__}:uses", budget=f"{__name__}:budget")
