"""The spec of `twostage` (RGB 3DGS, then semantics on frozen geometry from per-frame masks):
registration, what the scene must feed, and its budget (methods/twostage.py is the method)."""
from __future__ import annotations

from gsbench.config import setting
from gsbench.config_keys import Rule, at_least
from gsbench.method_table import MethodSpec
from gsbench.methods.rules import Drop, resolve_semantics

# the `twostage:` section
DEFAULTS = {
    "semantic_iterations": None,   # stage 2 steps (latents only, geometry frozen, no densification); null =
}                                  # train.iterations, the same semantic budget as GaussianDS (int >= 1 to override)
RULES: dict[str, Rule] = {"twostage.semantic_iterations": at_least(1, kind="int", integer=True)}


def resolve(cfg: dict, scene, drop: Drop) -> None:
    """RGB, then L_sem only: no depth prior; semantics (the shared `semantic` section) as the scene allows."""
    drop("priors.depth", "method twostage uses no depth prior (RGB, then semantics on frozen geometry)")
    resolve_semantics(cfg, scene, drop)


def uses(cfg: dict) -> dict:
    return {"depth_prior": False, "semantics": bool(setting(cfg, "semantic.loss"))}


def semantic_budget(cfg: dict) -> int:
    """Stage 2's steps: `twostage.semantic_iterations`, or (null) as many semantic steps as GaussianDS
    takes in the same config (`train.iterations`: each of its joint steps is a semantic step)."""
    v = setting(cfg, "twostage.semantic_iterations")
    return int(setting(cfg, "train.iterations")) if v is None else int(v)


def budget(cfg: dict) -> dict:
    sem = uses(cfg)["semantics"]
    return {"rgb_steps": int(setting(cfg, "train.iterations")), "semantic_steps": semantic_budget(cfg) if sem else 0,
            "schedule": "after rgb" if sem else "none"}


SPEC = MethodSpec(name="twostage", target="gsbench.methods.twostage:TwoStage", label="Two-stage",
                  section="twostage", resolve=f"{__name__}:resolve", uses=f"{__name__}:uses",
                  budget=f"{__name__}:budget", per_frame_masks=True,
                  defaults=DEFAULTS, rules=RULES, shared=("semantic",), order=20)
