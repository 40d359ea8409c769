"""The GaussianDS paper's numbers that gsbench compares itself with: each claim of the ablation
section with its section, table or figure, the compared rows and the paper's value, and the
latent-dimension table the dose figure marks (LATENT_DIM_MIOU).

Why beside the method: whoever changes GaussianDS sees what it is measured against; the report
(reports/claims_table.py) reads this table, sizes each claim against `paper` and gives the verdict. Row and
reference selectors use the collected column names: `axis.<config key>` for a grid axis, `method`.
Each number is the paper's as printed: a difference of two printed values is rounded to their decimals
(`_gap`), and `Claim.paper_decimals` carries them, so verdicts and printed text use the paper's precision.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from gsbench.methods.gaussiands.study_table import (
    AX_FORMULATION,
    AX_LATENT,
    AX_LOSSES,
    AX_NOISE_SEVERITY,
    AX_NOISE_TYPE,
    AX_ORDERING,
)
from gsbench.train.losses import EDGE_FLOOR

ROBUST_MARGIN_DB = 0.5  # gsbench's equivalence margin for "PSNR is robust" (dB), not the paper's
MAX = "max"             # selector value: the highest value of that axis among the study's runs
# Table tab-dims (waldo_kitchen): mIoU (%) by latent dimension d; the claims and the dose figure read it
LATENT_DIM_MIOU: dict[int, float] = {3: 61.42, 16: 62.83, 32: 61.32}
_D = LATENT_DIM_MIOU
# the ablation section prints every number it is compared on with two decimals (dB, %, r)
PAPER_DECIMALS = 2


def _gap(row: float, ref: float, decimals: int = PAPER_DECIMALS) -> float:
    """row - ref of two printed numbers, rounded to the decimals they are printed with: the difference of
    the paper, not its float64 neighbour (24.81 - 21.31 is 3.50, not 3.5000000000000036)."""
    return round(row - ref, decimals)


@dataclass(frozen=True)
class Claim:
    key: str
    text: str                  # the claim in words
    source: str                # section and table / figure of the paper
    study: str
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


_ALL = {AX_LOSSES[0]: True, AX_LOSSES[1]: True, AX_LOSSES[2]: True}
_NONE = {AX_LOSSES[0]: False, AX_LOSSES[1]: False, AX_LOSSES[2]: False}
_ABL = "Sec. Ablation Studies"
#: what an L_ds study must have been given (results.json metric -> floor): an edge map that marks something
DS_INPUTS = {"ds_edge_fraction": EDGE_FLOOR}
PAPER_CLAIMS: list[Claim] = [
    Claim("depth_ss_raw_psnr", "scale-shift beats raw L1 depth (PSNR)", f"{_ABL}, Table tab-depth-align (bench)",
          "depth_formulation", "psnr", +1, _gap(24.81, 21.31), "24.81 vs 21.31 dB",
          {AX_FORMULATION: "scale_shift"}, {AX_FORMULATION: "raw_l1"}),
    Claim("depth_mm_raw_psnr", "min-max beats raw L1 depth (PSNR)", f"{_ABL}, Table tab-depth-align (bench)",
          "depth_formulation", "psnr", +1, _gap(23.93, 21.31), "23.93 vs 21.31 dB",
          {AX_FORMULATION: "minmax"}, {AX_FORMULATION: "raw_l1"}),
    Claim("depth_ss_mm_psnr", "scale-shift beats min-max depth (PSNR)", f"{_ABL}, Table tab-depth-align (bench)",
          "depth_formulation", "psnr", +1, _gap(24.81, 23.93), "24.81 vs 23.93 dB",
          {AX_FORMULATION: "scale_shift"}, {AX_FORMULATION: "minmax"}),
    Claim("depth_ss_raw_mbiou", "scale-shift beats raw L1 depth (mBIoU)", f"{_ABL}, Table tab-depth-align (bench)",
          "depth_formulation", "mbiou", +1, _gap(91.99, 59.69), "91.99 vs 59.69 %",
          {AX_FORMULATION: "scale_shift"}, {AX_FORMULATION: "raw_l1"}),
    Claim("depth_ss_mm_mbiou", "scale-shift beats min-max depth (mBIoU)", f"{_ABL}, Table tab-depth-align (bench)",
          "depth_formulation", "mbiou", +1, _gap(91.99, 89.21), "91.99 vs 89.21 %",
          {AX_FORMULATION: "scale_shift"}, {AX_FORMULATION: "minmax"}),
    Claim("loss_depth_psnr", "L_depth alone raises PSNR over no auxiliary loss", f"{_ABL}, Table tab-ablation (bench)",
          "loss_subsets", "psnr", +1, _gap(22.46, 16.02), "22.46 vs 16.02 dB",
          {**_NONE, AX_LOSSES[0]: True}, _NONE),
    Claim("loss_ds_miou", "L_ds alone raises mIoU over no auxiliary loss", f"{_ABL}, Table tab-ablation (bench)",
          "loss_subsets", "miou", +1, _gap(84.40, 47.10), "84.40 vs 47.10 %",
          {**_NONE, AX_LOSSES[2]: True}, _NONE, inputs=DS_INPUTS),
    Claim("loss_all_psnr", "all three losses raise PSNR over none", f"{_ABL}, Table tab-ablation (bench)",
          "loss_subsets", "psnr", +1, _gap(24.81, 16.02), "24.81 vs 16.02 dB", _ALL, _NONE),
    Claim("loss_all_miou", "all three losses raise mIoU over none", f"{_ABL}, Table tab-ablation (bench)",
          "loss_subsets", "miou", +1, _gap(96.97, 47.10), "96.97 vs 47.10 %", _ALL, _NONE),
    Claim("loss_ds_mbiou", "adding L_ds to L_depth + L_tv raises mBIoU (boundary leakage)",
          f"{_ABL} (loss decomposition) and Sec. Boundary-Aware Semantic Segmentation", "loss_subsets", "mbiou", +1,
          None, "no number given", _ALL, {**_ALL, AX_LOSSES[2]: False}, inputs=DS_INPUTS),
    Claim("ordering_pose_random", "pose-nearest ordering raises adjacent mask IoU over random",
          f"{_ABL}, Table tab-ordering (five 3D-OVS scenes)", "ordering", "ordering_adjacent_mask_iou_strict", +1,
          _gap(53.21, 33.92), "53.21 vs 33.92 %", {AX_ORDERING: "pose"}, {AX_ORDERING: "random"}),
    Claim("ordering_pose_filename", "pose-nearest ordering raises adjacent mask IoU over filename order",
          f"{_ABL}, Table tab-ordering (five 3D-OVS scenes)", "ordering", "ordering_adjacent_mask_iou_strict", +1,
          _gap(53.21, 50.85), "53.21 vs 50.85 %", {AX_ORDERING: "pose"}, {AX_ORDERING: "filename"}),
    Claim("lambda_depth_r", "lambda_depth correlates negatively with mIoU",
          f"{_ABL} (sensitivity), Fig. fig-lambda-sweep", "lambda_grid", "miou", -1, -0.89, "Pearson r",
          correlation="axis.gaussiands.lambdas.depth"),
    Claim("lambda_sem_r", "lambda_sem correlates positively with mIoU",
          f"{_ABL} (sensitivity), Fig. fig-lambda-sweep", "lambda_grid", "miou", +1, 0.69, "Pearson r",
          correlation="axis.gaussiands.lambdas.sem"),
    Claim("latent_16_3", "mIoU rises from d = 3 to d = 16", f"{_ABL}, Table tab-dims (waldo_kitchen)",
          "latent_dim", "miou", +1, _gap(_D[16], _D[3]), f"{_D[16]:.2f} vs {_D[3]:.2f} %",
          {"method": "gaussiands", AX_LATENT: 16}, {"method": "gaussiands", AX_LATENT: 3}),
    Claim("latent_32_16", "mIoU falls from d = 16 to d = 32", f"{_ABL}, Table tab-dims (waldo_kitchen)",
          "latent_dim", "miou", -1, _gap(_D[32], _D[16]), f"{_D[32]:.2f} vs {_D[16]:.2f} %",
          {"method": "gaussiands", AX_LATENT: 32}, {"method": "gaussiands", AX_LATENT: 16}),
    Claim("noise_motion_blur", "motion blur on the depth prior lowers PSNR (the most of the four kinds)",
          "Sec. Multi-view 3D Reconstruction (robustness), Fig. fig-noise", "depth_noise", "psnr", -1, None,
          "figure only, no number", {AX_NOISE_TYPE: "motion_blur", AX_NOISE_SEVERITY: MAX},
          {AX_NOISE_TYPE: None, AX_NOISE_SEVERITY: 0}),
    *[Claim(f"noise_{kind}", f"PSNR is robust to {kind.replace('_', '-')} noise on the depth prior",
            "Sec. Multi-view 3D Reconstruction (robustness), Fig. fig-noise", "depth_noise", "psnr", 0, None,
            f"figure only: 'remarkably robust'; gsbench margin +-{ROBUST_MARGIN_DB} dB",
            {AX_NOISE_TYPE: kind, AX_NOISE_SEVERITY: MAX}, {AX_NOISE_TYPE: None, AX_NOISE_SEVERITY: 0})
      for kind in ("gaussian", "poisson", "salt_pepper")],
]

__all__ = ["Claim", "PAPER_CLAIMS", "ROBUST_MARGIN_DB", "MAX"]
