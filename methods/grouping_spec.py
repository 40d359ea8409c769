"""The spec of `grouping` (a Gaussian Grouping-style joint identity baseline): registration, what the
scene must feed, and its budget (methods/grouping.py is the method)."""
from __future__ import annotations

from gsbench.config import setting
from gsbench.config_keys import Rule, at_least, positive, unit
from gsbench.method_table import MethodSpec
from gsbench.methods.rules import Drop, semantic_source, switch_off

# the `grouping:` section: the paper's recipe
DEFAULTS = {
    "identity_dim": 16,        # identity encoding per Gaussian, rendered like colour (LR: train.lr.semantic)
    "num_classes": 256,        # classifier outputs (>= mask tracks + 1 for the no-mask class 0); null = tracks + 1
    "classifier_lr": 5.0e-4,   # Adam on the classifier
    "losses": {
        "identity": True,      # cross-entropy of the classified rendered identity vs the propagated mask ids
        "reg3d": True,         # KL between a Gaussian's class distribution and its k nearest neighbours'
    },
    "lambdas": {
        "identity": 1.0,       # times CE / log(num_classes)
        "reg3d": 2.0,          # times mean KL / num_classes
    },
    "reg3d": {
        "interval": 5,         # every this many steps, from the first
        "k": 5,                # neighbours by position (the Gaussian itself included)
        "sample_size": 1000,   # Gaussians regularised per application
        "max_points": 200000,  # neighbours searched among a random subset of at most this many
    },
    "removal_threshold": 0.3,  # removal: Gaussians whose class probability for the query's track exceeds this
}
RULES: dict[str, Rule] = {
    "grouping.identity_dim": at_least(1),
    "grouping.num_classes": at_least(2, integer=True, nullable=True),   # null = tracks + 1
    "grouping.classifier_lr": positive(),
    "grouping.lambdas.identity": at_least(0),
    "grouping.lambdas.reg3d": at_least(0),
    "grouping.reg3d.interval": at_least(1),
    "grouping.reg3d.k": at_least(1),
    "grouping.reg3d.sample_size": at_least(1),
    "grouping.reg3d.max_points": at_least(1),
    "grouping.removal_threshold": unit(),
}


def resolve(cfg: dict, scene, drop: Drop) -> None:
    """No depth prior and no autoencoder; identity and 3D-regulariser losses as the scene allows."""
    on = cfg["grouping"]["losses"]
    drop("priors.depth", "method grouping uses no depth prior (RGB + identity classification)")
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
    return {"depth_prior": False, "semantics": bool(setting(cfg, "grouping.losses.identity"))}


def budget(cfg: dict) -> dict:
    """Joint training: every step is also a semantic step when the identity loss is on."""
    steps = int(setting(cfg, "train.iterations"))
    sem = uses(cfg)["semantics"]
    return {"rgb_steps": steps, "semantic_steps": steps if sem else 0, "schedule": "joint" if sem else "none"}


SPEC = MethodSpec(name="grouping", target="gsbench.methods.grouping:GaussianGrouping",
                  label="Gaussian Grouping (style)", section="grouping", resolve=f"{__name__}:resolve",
                  uses=f"{__name__}:uses", budget=f"{__name__}:budget", defaults=DEFAULTS, rules=RULES,
                  order=30)
