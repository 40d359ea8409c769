"""The spec of `gaussiands`, the reference method: registration, its config section (defaults, ranges,
choices), what the scene must feed, and its budget. The method is methods/gaussiands/method.py; the
paper's numbers and studies are study_table.py beside it. It reads the shared `semantic` section (L_sem on, d, the
autoencoder) and its own `gaussiands` section below."""
from __future__ import annotations

from gsbench.config import setting
from gsbench.config_keys import Rule, at_least, one_of, positive
from gsbench.method_table import MethodSpec
from gsbench.methods.rules import Drop, depth_source, resolve_semantics, switch_off

# the depth-loss forms and L_ds averages gsbench/train/losses.py implements (a test keeps them equal)
DEPTH_FORMULATIONS = ("none", "raw_l1", "minmax", "scale_shift", "pearson")
DS_AVERAGES = ("pixels", "edges")
# where L_sem's and L_ds's gradient may go (docs/methods.md, "Where GaussianDS's PSNR goes at small d"):
# joint = one render, into the latents, the geometry and the densification statistic (null, the default)
SEM_GEOMETRY = ("joint", "no_densify", "detached")

# the `gaussiands:` section, with the paper's values
DEFAULTS = {
    "depth_formulation": "scale_shift",   # none | raw_l1 | minmax | scale_shift | pearson
    "losses": {"depth": True, "tv": True, "ds": True},   # terms on/off (ablation: 8 subsets); L_sem: semantic.loss
    "lambdas": {"depth": 0.01, "tv": 1.5, "sem": 5.0, "ds": 1.0},
    "tv_eps": 1.0e-6,
    "ds_average": "pixels",   # L_ds averages |E_d (S_hat - S)| over pixels with a target (pixels) | edge pixels (edges)
    "edges": {                # E_d: Canny on the depth prior, dilated
        "canny_low": 50,
        "canny_high": 150,
        "dilate": 1,
        "size": None,         # short side (px) Canny runs at when the prior is larger (518: Depth Anything's output);
    },                        # null = the training size
    "min_valid_pixels": 10,
    "sem_geometry": None,     # null = joint | no_densify | detached: see SEM_GEOMETRY (null: left out of run ids)
}
# layout 1 (gsbench up to d113fae) kept d, the autoencoder and L_sem's switch here; twostage read them too
MOVED = {"gaussiands.latent_dim": "semantic.latent_dim", "gaussiands.autoencoder": "semantic.autoencoder",
         "gaussiands.losses.sem": "semantic.loss"}
RULES: dict[str, Rule] = {
    "gaussiands.depth_formulation": one_of(*DEPTH_FORMULATIONS),
    "gaussiands.ds_average": one_of(*DS_AVERAGES),
    **{f"gaussiands.lambdas.{k}": at_least(0) for k in ("depth", "tv", "sem", "ds")},
    "gaussiands.tv_eps": positive(),
    "gaussiands.edges.canny_low": at_least(0),
    "gaussiands.edges.canny_high": at_least(0),
    "gaussiands.edges.dilate": at_least(0),
    "gaussiands.edges.size": at_least(8, kind="int", integer=True),   # null = Canny at the training size
    "gaussiands.min_valid_pixels": at_least(1),
    "gaussiands.sem_geometry": one_of(*SEM_GEOMETRY, kind="str"),   # null = joint
}


def resolve(cfg: dict, scene, drop: Drop) -> None:
    """Depth terms off without a depth prior (or with depth_formulation none); semantics as the scene allows
    (L_sem is `semantic.loss`; L_ds needs the semantic targets too)."""
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
    resolve_semantics(cfg, scene, drop, also=(on, "gaussiands.losses", ("ds",)))


def uses(cfg: dict) -> dict:
    ds = setting(cfg, "gaussiands.losses.ds")
    depth = setting(cfg, "gaussiands.losses.depth") and setting(cfg, "gaussiands.depth_formulation") != "none"
    depth_terms = bool(depth) or bool(ds)
    return {"depth_prior": depth_terms, "semantics": bool(setting(cfg, "semantic.loss") or ds)}


def budget(cfg: dict) -> dict:
    """Joint optimisation from scratch: every step is a semantic step when a semantic loss is on."""
    steps = int(setting(cfg, "train.iterations"))
    sem = uses(cfg)["semantics"]
    return {"rgb_steps": steps, "semantic_steps": steps if sem else 0, "schedule": "joint" if sem else "none"}


SPEC = MethodSpec(name="gaussiands", target="gsbench.methods.gaussiands.method:GaussianDS", label="GaussianDS",
                  section="gaussiands", resolve=f"{__name__}:resolve", uses=f"{__name__}:uses",
                  budget=f"{__name__}:budget", defaults=DEFAULTS, rules=RULES, shared=("semantic",), order=40,
                  moved=MOVED)
