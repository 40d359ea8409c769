"""The one table of studies: what each grid study varies, its label, the reference row the others are
compared with, and whether it feeds the main tables. Grids check their axes against it
(gsbench/grids/grid_file.py) and the report reads labels, references and the main studies from it.

A study is the name a grid records on every run (`study:` in gsbench/grids/*.yaml); `axes` are the
config keys (or `method`) its grids may vary; `reference` selects the row every other row of the
study is compared with, by the same keys.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional


@dataclass(frozen=True)
class Study:
    name: str
    label: str
    axes: tuple[str, ...]
    reference: dict = field(default_factory=dict)      # config key (or "method") -> value; {} = none
    reference_text: str = ""
    main: bool = False                                 # feeds Tables I-III (reconstruction)
    kind: str = "paper"                                # paper | control | smoke

    def reference_columns(self) -> dict[str, Any]:
        """The reference selector over collected columns (`axis.<key>`, or `method`)."""
        return {column(k): v for k, v in self.reference.items()}


def column(key: str) -> str:
    """The collected column of a grid axis key: `method` stays, any config key is `axis.<key>`."""
    return key if key == "method" else f"axis.{key}"


_LOSSES = ("gaussiands.losses.depth", "gaussiands.losses.tv", "gaussiands.losses.ds")
_NOISE = ("priors.depth.noise.type", "priors.depth.noise.severity")
_LAMBDAS = ("gaussiands.lambdas.depth", "gaussiands.lambdas.tv", "gaussiands.lambdas.sem", "gaussiands.lambdas.ds")

# the collected columns of the studies' axes, as the report and the paper's claims select rows by them
AX_ORDERING = column("priors.ordering")
AX_FORMULATION = column("gaussiands.depth_formulation")
AX_LOSSES = [column(k) for k in _LOSSES]
AX_LATENT = column("semantic.latent_dim")
AX_LAMBDAS = [column(k) for k in _LAMBDAS]
AX_NOISE_TYPE, AX_NOISE_SEVERITY = (column(k) for k in _NOISE)

_ALL: tuple[Study, ...] = (
    Study("reconstruction", "Reconstruction and segmentation per scene (Tables I-III)", ("method",),
          {"method": "gaussiands"}, "GaussianDS (the paper's method) on the same scene", main=True),
    Study("ordering", "Pseudo-video ordering", ("priors.ordering",), {"priors.ordering": "pose"},
          "pose-nearest ordering (the paper's method)"),
    Study("depth_formulation", "Depth supervision formulation", ("gaussiands.depth_formulation",),
          {"gaussiands.depth_formulation": "scale_shift"}, "scale-shift aligned depth (the paper's method)"),
    Study("loss_subsets", "Loss subsets", _LOSSES, {k: True for k in _LOSSES},
          "all three losses on (the paper's full objective)"),
    Study("latent_dim", "Latent dimension d", ("semantic.latent_dim", "method"),
          {"method": "gaussiands", "semantic.latent_dim": 3}, "d = 3 (the paper's default)"),
    Study("lambda_grid", "Lambda grid (hyper-parameter sensitivity)", _LAMBDAS),
    Study("depth_noise", "Depth-noise robustness", _NOISE, {_NOISE[0]: None, _NOISE[1]: 0},
          "the clean depth prior (severity 0)"),
    Study("control_depth", "Control: few-view L_depth with an exact prior", ("train.views", "gaussiands.lambdas.depth"),
          kind="control"),
    Study("control_depth_noise", "Control: depth noise at lambda_depth 1, few views", _NOISE, kind="control"),
    Study("control_ds", "Control: edge-averaged L_ds with capped Gaussians", ("gaussiands.losses.ds",),
          kind="control"),
    Study("control_latent", "Control: latent d on a 14-class scene", ("semantic.latent_dim",), kind="control"),
    Study("control_sem", "Control: lambda_sem 0 against 5", ("gaussiands.lambdas.sem",), kind="control"),
    Study("tiny-test", "Smoke grid (latent d x L_ds)", ("semantic.latent_dim", "gaussiands.losses.ds"),
          {"semantic.latent_dim": 3, "gaussiands.losses.ds": True}, "d = 3 with L_ds on (the defaults)",
          kind="smoke"),
)
STUDIES: dict[str, Study] = {s.name: s for s in _ALL}
# runs that feed the main tables: standalone runs (no study) and the main studies
MAIN_STUDIES: tuple[Optional[str], ...] = (None, *(s.name for s in _ALL if s.main))

__all__ = ["Study", "STUDIES", "MAIN_STUDIES", "column", "AX_ORDERING", "AX_FORMULATION", "AX_LOSSES",
           "AX_LATENT", "AX_LAMBDAS", "AX_NOISE_TYPE", "AX_NOISE_SEVERITY"]
