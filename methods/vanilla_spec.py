"""The spec of `vanilla` (RGB-only 3DGS, the paper's "3DGS" column): registration, what the scene
must feed, and its budget. Read by the method table without importing the method (methods/vanilla.py)."""
from __future__ import annotations

from gsbench.config import setting
from gsbench.method_table import MethodSpec
from gsbench.methods.rules import Drop


def resolve(cfg: dict, scene, drop: Drop) -> None:
    """Every prior off: the method is RGB only (it reads no shared section, so `semantic` leaves its run id)."""
    for part in ("priors.depth", "priors.masks", "priors.features", "semantic_channels"):
        drop(part, "method vanilla is RGB only")


def uses(cfg: dict) -> dict:
    return {"depth_prior": False, "semantics": False}


def budget(cfg: dict) -> dict:
    return {"rgb_steps": int(setting(cfg, "train.iterations")), "semantic_steps": 0, "schedule": "none"}


SPEC = MethodSpec(name="vanilla", target="gsbench.methods.vanilla:Vanilla", label="3DGS (vanilla)", section=None,
                  resolve=f"{__name__}:resolve", uses=f"{__name__}:uses", budget=f"{__name__}:budget",
                  order=10)
