"""The spec of `lift` (training-free lifting: RGB 3DGS, then each Gaussian gets the blending-weighted mean
of the per-view mask features it contributes to): registration, what the scene must feed, and its
budget (methods/lift.py is the method)."""
from __future__ import annotations

from gsbench.config import setting
from gsbench.config_keys import Rule, at_least
from gsbench.method_table import MethodSpec
from gsbench.methods.rules import Drop, semantic_source, switch_off

# the `lift:` section
DEFAULTS = {
    "semantics": True,   # lift the mask features onto the trained Gaussians (off, or a scene without
    #                      semantics: an RGB-only model, as vanilla)
    "top_k": None,       # null: every Gaussian a pixel blends; k >= 1: only each pixel's k largest
    #                      blending weights count (Dr. Splat style)
}
RULES: dict[str, Rule] = {"lift.top_k": at_least(1, kind="int", integer=True, nullable=True)}


def resolve(cfg: dict, scene, drop: Drop) -> None:
    """No depth prior, no autoencoder, no L_sem; the lifted features need masks and features the scene
    can feed (the same checks as the semantic methods)."""
    drop("priors.depth", "method lift uses no depth prior (RGB, then features lifted onto frozen geometry)")
    ok, why = semantic_source(cfg, scene)
    if not ok:
        switch_off(cfg["lift"], ("semantics",), "lift", why, drop)
    if not cfg["lift"]["semantics"]:
        reason = why if not ok else "nothing uses it (lift.semantics is off)"
        for part in ("priors.masks", "priors.features", "semantic_channels"):
            drop(part, reason)


def uses(cfg: dict) -> dict:
    return {"depth_prior": False, "semantics": bool(setting(cfg, "lift.semantics"))}


def budget(cfg: dict) -> dict:
    """RGB steps only: the lifting is one pass over the training views, no optimisation step."""
    return {"rgb_steps": int(setting(cfg, "train.iterations")), "semantic_steps": 0,
            "schedule": "lifted after rgb" if uses(cfg)["semantics"] else "none"}


SPEC = MethodSpec(name="lift", target="gsbench.methods.lift:Lift", label="Lift (training-free)", section="lift",
                  resolve=f"{__name__}:resolve", uses=f"{__name__}:uses", budget=f"{__name__}:budget",
                  per_frame_masks=True, defaults=DEFAULTS, rules=RULES, order=25)
