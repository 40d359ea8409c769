"""The spec of `twostage` (RGB 3DGS, then semantics on frozen geometry from per-frame masks):
registration, what the scene must feed, and its budget (methods/twostage.py is the method)."""
from __future__ import annotations

from gsbench.method_table import MethodSpec
from gsbench.methods.rules import Drop, resolve_semantics


def resolve(cfg: dict, scene, drop: Drop) -> None:
    """RGB + L_sem only: no depth prior, no L_depth / L_tv / L_ds; semantics as the scene allows."""
    on = cfg["gaussiands"]["losses"]
    on["depth"] = on["tv"] = on["ds"] = False
    drop("priors.depth", "method twostage uses no depth prior (RGB, then semantics on frozen geometry)")
    for k in ("depth", "tv", "ds"):
        drop(f"gaussiands.losses.{k}", "method twostage: RGB + L_sem only")
    resolve_semantics(cfg, scene, drop)


def uses(cfg: dict) -> dict:
    return {"depth_prior": False, "semantics": bool(cfg["gaussiands"]["losses"]["sem"])}


def semantic_budget(cfg: dict) -> int:
    """Stage 2's steps: `twostage.semantic_iterations`, or (null) as many semantic steps as GaussianDS
    takes in the same config (`train.iterations`: each of its joint steps is a semantic step)."""
    v = cfg["twostage"]["semantic_iterations"]
    return int(cfg["train"]["iterations"]) if v is None else int(v)


def budget(cfg: dict) -> dict:
    sem = uses(cfg)["semantics"]
    return {"rgb_steps": int(cfg["train"]["iterations"]), "semantic_steps": semantic_budget(cfg) if sem else 0,
            "schedule": "after rgb" if sem else "none"}


SPEC = MethodSpec(name="twostage", target="gsbench.methods.twostage:TwoStage", label="Two-stage",
                  section="twostage", resolve=f"{__name__}:resolve", uses=f"{__name__}:uses",
                  budget=f"{__name__}:budget", per_frame_masks=True)
