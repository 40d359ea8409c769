"""The spec of `example_l1`: its registration, its own config section with defaults, what it reads
from the scene and its budget. gsbench finds it through the `gsbench.methods` entry point."""
from __future__ import annotations

from gsbench.method_table import MethodSpec
from gsbench.methods import vanilla_spec


def resolve(cfg: dict, scene, drop) -> None:
    """As vanilla (RGB only), with the D-SSIM weight taken from this method's own section."""
    vanilla_spec.resolve(cfg, scene, drop)
    cfg["train"]["lambda_dssim"] = float(cfg["example_l1"]["lambda_dssim"])


def uses(cfg: dict) -> dict:
    return vanilla_spec.uses(cfg)


def budget(cfg: dict) -> dict:
    return vanilla_spec.budget(cfg)


SPEC = MethodSpec(name="example_l1", target="gsbench_example_plugin.method:ExampleL1", label="Example L1 (plugin)",
                  section="example_l1", resolve=f"{__name__}:resolve", uses=f"{__name__}:uses",
                  budget=f"{__name__}:budget", defaults={"lambda_dssim": 0.0})
