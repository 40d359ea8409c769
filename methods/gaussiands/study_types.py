"""The shapes of the study table (methods/gaussiands/study_table.py): a study, the paper's claims and the
positive controls declared on it, and the regimes the claims page reads them in. Only types and the
helpers their declarations use; the declarations themselves are in the study table.

A study is the name a grid records on every run (`study:` in gsbench/grids/*.yaml). Row and reference
selectors of claims and controls use the collected column names: `axis.<config key>` for a grid axis,
`method` (`column`).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

MAX = "max"             # selector value: the highest value of that axis among the study's runs
# the ablation section prints every number it is compared on with two decimals (dB, %, r)
PAPER_DECIMALS = 2


def column(key: str) -> str:
    """The collected column of a grid axis key: `method` stays, any config key is `axis.<key>`."""
    return key if key == "method" else f"axis.{key}"


def gap(row: float, ref: float, decimals: int = PAPER_DECIMALS) -> float:
    """row - ref of two printed numbers, rounded to the decimals they are printed with: the difference of
    the paper, not its float64 neighbour (24.81 - 21.31 is 3.50, not 3.5000000000000036)."""
    return round(row - ref, decimals)


@dataclass(frozen=True)
class Claim:
    """One claim of the paper, declared on the study that tests it (the study table fills in `study`)."""
    key: str
    text: str                  # the claim in words
    source: str                # section and table / figure of the paper
    metric: str                # logical metric ('miou' resolves per protocol)
    direction: int             # +1 / -1: the paper's sign of (row - reference); 0: no effect claimed
    paper: float | None        # the paper's number (difference or r) in display units, None = none given
    paper_note: str = ""
    row: dict = field(default_factory=dict)        # axis -> value of the compared row
    reference: dict = field(default_factory=dict)  # axis -> value of the row it is compared with
    correlation: str | None = None                 # lambda axis: Pearson r with the metric instead
    # metric -> floor: what the compared row's runs must have been given for the study to see the mechanism
    # (the mean over its runs); below it an absent effect reads 'blind' (reports/claims_table.py)
    inputs: dict = field(default_factory=dict)
    paper_decimals: int = PAPER_DECIMALS           # decimals the paper prints `paper` with
    # a robustness claim's equivalence margin in display units (None: the study table's ROBUST_MARGIN_DB);
    # with log_ratio, in natural-log units of the ratio row / reference
    margin: float | None = None
    log_ratio: bool = False    # compare log(metric): the effect is the ratio row / reference (e.g. FPS)
    unguarded: str = ""        # why no positive control applies (a timing, not a mechanism); "" = guarded
    study: str = ""                                # the declaring study (set by the study table)


@dataclass(frozen=True)
class Control:
    """A positive control, declared on its control study (the study table fills in `study`): a setting
    where the mechanism's effect must exist if the implementation is right (reports/controls.py)."""
    key: str
    text: str
    metric: str
    direction: int                 # the side the effect must be on: +1 / -1 (row - reference)
    axes: tuple[str, ...]          # the columns that tell the control's rows apart
    reference: dict                # axis -> value of the reference row
    guards: tuple[str, ...] = ()   # claim keys that are blind when this control is not marked
    inputs: dict = field(default_factory=dict)   # metric -> floor: what a row must have been given
    where: dict = field(default_factory=dict)    # axis -> the values the control's runs are taken from ({} = all)
    study: str = ""                # the declaring study (set by the study table)


@dataclass(frozen=True)
class Study:
    """One study: what its grids may vary, its label and reference row, the grids of the claims plan that
    record it, and the claims (a paper study) or positive controls (a control study) read from its runs."""
    name: str
    label: str
    axes: tuple[str, ...]
    reference: dict = field(default_factory=dict)      # config key (or "method") -> value; {} = none
    reference_text: str = ""
    main: bool = False                                 # feeds Tables I-III (reconstruction)
    kind: str = "paper"                                # paper | control | smoke
    claims_grids: tuple[str, ...] = ()                 # grids `gsbench claims` runs for it: shipped names or paths
    claims: tuple[Claim, ...] = ()
    controls: tuple[Control, ...] = ()

    def reference_columns(self) -> dict[str, Any]:
        """The reference selector over collected columns (`axis.<key>`, or `method`)."""
        return {column(k): v for k, v in self.reference.items()}

    def declared_claims(self) -> list[Claim]:
        """Its claims, each naming this study."""
        return [replace(c, study=self.name) for c in self.claims]

    def declared_controls(self) -> list[Control]:
        """Its controls, each naming this study."""
        return [replace(c, study=self.name) for c in self.controls]


@dataclass(frozen=True)
class Regime:
    """Where a cell ran, as its stored config says (reports/regimes.py derives it): the scene, how many
    training views it trained on (`train.views`; None = every view of the scene's training split), the
    preset (recognised by its schedule) and the prior providers. A control guards a claim only in the
    claim's regime; the one difference allowed is the exact version of the claim's depth prior
    (docs/grids.md, "Regimes")."""
    scene: str
    views: int | None
    preset: str
    depth: str                       # depth provider: gt, sfm, sparse, depth-anything, none
    depth_distortion: float | None   # the gt provider's distortion (0 = exact up to scale and shift); else None
    masks: str                       # masks provider: simulated, gt, sam2
    features: str                    # features provider: text-aligned, openclip

    def exact_depth(self) -> "Regime | None":
        """The same regime with the exact version of its depth prior (gt at distortion 0); None when the
        depth prior has no exact version or already is one."""
        if self.depth != "gt" or self.depth_distortion == 0.0:
            return None
        return replace(self, depth_distortion=0.0)


@dataclass(frozen=True)
class DeclaredRegime:
    """A column of the claims page's claim x regime matrix: its name, whether its scene is generated
    ('synthetic') or a capture ('real'), and the regime itself."""
    name: str
    kind: str
    regime: Regime
    why: str


__all__ = ["MAX", "PAPER_DECIMALS", "column", "gap", "Claim", "Control", "Study", "Regime", "DeclaredRegime"]
