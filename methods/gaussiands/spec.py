"""The spec of `gaussiands`, the reference method: registration, what the scene must feed, and its
budget. The method is methods/gaussiands/method.py; the paper's numbers are paper.py beside it."""
from __future__ import annotations

from gsbench.method_table import MethodSpec
from gsbench.methods.rules import Drop, depth_source, resolve_semantics, switch_off


def resolve(cfg: dict, scene, drop: Drop) -> None:
    """Depth terms off without a depth prior (or with depth_formulation none); semantics as the scene allows."""
    g = cfg["gaussiands"]
    on = g["losses"]
    if g["depth_formulation"] == "none" and on["depth"]:
        on["depth"] = False
        drop("gaussiands.losses.depth", "gaussiands.depth_formulation=none")
    ok, why = depth_source(cfg, scene)
    if not ok:
        switch_off(on, ("depth", "ds"), "gaussiands.losses", f"no depth prior: {why}", drop)
        drop("priors.depth", why)
    elif not (on["depth"] or on["ds"]):
        drop("priors.depth", "nothing uses it (gaussiands.losses.depth and .ds are off)")
    resolve_semantics(cfg, scene, drop)


def uses(cfg: dict) -> dict:
    g = cfg["gaussiands"]
    on = g["losses"]
    depth_terms = bool(on["depth"] and g["depth_formulation"] != "none") or bool(on["ds"])
    return {"depth_prior": depth_terms, "semantics": bool(on["sem"] or on["ds"])}


def budget(cfg: dict) -> dict:
    """Joint optimisation from scratch: every step is a semantic step when a semantic loss is on."""
    steps = int(cfg["train"]["iterations"])
    sem = uses(cfg)["semantics"]
    return {"rgb_steps": steps, "semantic_steps": steps if sem else 0, "schedule": "joint" if sem else "none"}


SPEC = MethodSpec(name="gaussiands", target="gsbench.methods.gaussiands.method:GaussianDS", label="GaussianDS",
                  section="gaussiands", resolve=f"{__name__}:resolve", uses=f"{__name__}:uses",
                  budget=f"{__name__}:budget")
