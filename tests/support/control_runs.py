"""Hand-written positive-control runs for the claims tests: every control that guards a claim, with an
effect far beyond its interval on the expected side, so that it is marked in the regime its runs'
config gives (reports/regimes.py). The verdict-word tests put them beside their claim runs, in the same
regime, so a verdict whose interval includes zero is read as a verdict and not as "blind".
"""
from __future__ import annotations

import copy
from pathlib import Path

from report_runs import write_run

# control study -> (metric, reference grid, compared grid, effect of the compared row, in metric units)
CONTROL_RUNS = {
    "control_depth": ("psnr", {"train.views": 3, "gaussiands.lambdas.depth": 0.0},
                      {"train.views": 3, "gaussiands.lambdas.depth": 1.0}, +1.0),
    "control_depth_noise": ("psnr", {"priors.depth.noise.type": None, "priors.depth.noise.severity": 0},
                            {"priors.depth.noise.type": "gaussian", "priors.depth.noise.severity": 5}, -1.0),
    "control_ds": ("mbiou", {"gaussiands.losses.ds": False}, {"gaussiands.losses.ds": True}, +0.05),
    "control_latent": ("miou", {"semantic.latent_dim": 1}, {"semantic.latent_dim": 16}, +0.1),
    "control_sem": ("miou", {"gaussiands.lambdas.sem": 0.0}, {"gaussiands.lambdas.sem": 5.0}, +0.1),
}
SEEDS = (0, 1, 2)


def with_grid(config: dict | None, grid: dict) -> dict | None:
    """A copy of `config` with the grid's dotted keys set in it (a resolved config holds its axis values);
    None stays None."""
    if config is None:
        return None
    out = copy.deepcopy(config)
    for key, value in grid.items():
        node = out
        *path, last = key.split(".")
        for part in path:
            node = node.setdefault(part, {})
        node[last] = value
    return out


def write_marked_controls(root: Path, scene: str = "bench", protocol: str = "3dovs", config: dict | None = None,
                          studies: tuple[str, ...] | None = None, prefix: str = "ctl") -> None:
    """Every control of CONTROL_RUNS (or `studies`) on 3 seeds, its compared row moved by its effect times
    1.00 / 1.02 / 0.99 against the reference (a paired interval far from zero); `config` is merged into
    every run's config (its regime)."""
    for study, (metric, ref, row, effect) in CONTROL_RUNS.items():
        if studies is not None and study not in studies:
            continue
        name = {"psnr": "psnr", "mbiou": f"mbiou_{protocol}", "miou": f"miou_{protocol}"}[metric]
        base = 20.0 if metric == "psnr" else 0.5
        for s, scale in zip(SEEDS, (1.0, 1.02, 0.99)):
            for tag, grid, move in (("ref", ref, 0.0), ("row", row, effect * scale)):
                write_run(root, f"{prefix}/{study}_{tag}_{s}", method="gaussiands", scene=scene, seed=s, study=study,
                          grid=grid, protocol=protocol, metrics={name: base + 0.1 * s + move},
                          config_extra=with_grid(config, grid))
