"""The one home of the paper's studies, their claims, their positive controls and the claims plan: each
study is declared once, with what its grids may vary, its label and reference row, the grids
`gsbench claims` runs for it, and the claims (a paper study) or controls (a control study) read from
its runs; the regimes the claims page reads them in close the table. Grids (gsbench/grids/grid_file.py,
claims_plan.py) and the report (reports/display.py, claims_table.py, controls.py, claims_page.py) receive
all of it as data from here, through the functions at the bottom, which read `DECLARED` when called.

Adding a claim on a new study is one `Study(...)` in `DECLARED` plus its grid files (docs/grids.md,
"Adding a claim"). `claims_grids` and `kind` are written as literals: scripts/gpu_claims.py reads them
from this file without importing gsbench.

Why beside the method: these are the paper's studies of GaussianDS, so whoever changes GaussianDS sees
what it is measured against; and on floor 2 both the grids (floor 3) and the reports (floor 4) may read
it, while the ground floor names no method's keys (docs/architecture.md). Each paper number is the
paper's as printed: a difference of two printed values is rounded to their decimals (`gap`), and
`Claim.paper_decimals` carries them, so verdicts and printed text use the paper's precision.
"""
from __future__ import annotations

import math
from typing import Optional

from gsbench.methods.gaussiands.study_types import (MAX, PAPER_DECIMALS, Claim, Control, DeclaredRegime,  # isort: skip
                                                     Regime, Study, column, gap)
from gsbench.train.losses import EDGE_FLOOR

ROBUST_MARGIN_DB = 0.5  # gsbench's equivalence margin for "PSNR is robust" (dB), not the paper's
# Table tab-dims (waldo_kitchen): mIoU (%) by latent dimension d; the claims and the dose figure read it
LATENT_DIM_MIOU: dict[int, float] = {3: 61.42, 16: 62.83, 32: 61.32}
_D = LATENT_DIM_MIOU

_LOSSES = ("gaussiands.losses.depth", "gaussiands.losses.tv", "gaussiands.losses.ds")
_NOISE = ("priors.depth.noise.type", "priors.depth.noise.severity")
_LAMBDAS = ("gaussiands.lambdas.depth", "gaussiands.lambdas.tv", "gaussiands.lambdas.sem", "gaussiands.lambdas.ds")

# the collected columns of the studies' axes, as the report, the claims and the controls select rows by them
AX_ORDERING = column("priors.ordering")
AX_FORMULATION = column("gaussiands.depth_formulation")
AX_LOSSES = [column(k) for k in _LOSSES]
AX_LATENT = column("semantic.latent_dim")
AX_LAMBDAS = [column(k) for k in _LAMBDAS]
AX_NOISE_TYPE, AX_NOISE_SEVERITY = (column(k) for k in _NOISE)
AX_VIEWS = column("train.views")   # the few-view count the depth controls vary beside lambda_depth

_ALL = {AX_LOSSES[0]: True, AX_LOSSES[1]: True, AX_LOSSES[2]: True}
_NONE = {AX_LOSSES[0]: False, AX_LOSSES[1]: False, AX_LOSSES[2]: False}
_ABL = "Sec. Ablation Studies"
_DEPTH_ALIGN = f"{_ABL}, Table tab-depth-align (bench)"
_TAB_ABL = f"{_ABL}, Table tab-ablation (bench)"
_ORDER_TAB = f"{_ABL}, Table tab-ordering (five 3D-OVS scenes)"
_SWEEP = f"{_ABL} (sensitivity), Fig. fig-lambda-sweep"
_DIMS = f"{_ABL}, Table tab-dims (waldo_kitchen)"
_FIG_NOISE = "Sec. Multi-view 3D Reconstruction (robustness), Fig. fig-noise"
#: what an L_ds study must have been given (results.json metric -> floor): an edge map that marks something
DS_INPUTS = {"ds_edge_fraction": EDGE_FLOOR}
_NOISE_CLEAN = {AX_NOISE_TYPE: None, AX_NOISE_SEVERITY: 0}
_DEPTH_CLAIMS = ("depth_ss_raw_psnr", "depth_mm_raw_psnr", "depth_ss_mm_psnr", "depth_ss_raw_mbiou",
                 "depth_ss_mm_mbiou", "loss_depth_psnr", "lambda_depth_r",
                 # the paper credits GaussianDS's colour over vanilla and Grouping to its depth prior
                 "rec_psnr_vanilla", "rec_ssim_vanilla", "rec_lpips_vanilla", "rec_psnr_grouping",
                 "rec_ssim_grouping", "rec_lpips_grouping")
_FEW = (AX_VIEWS, AX_LAMBDAS[0])
# the headline comparisons (Tables tab-rec-main, tab-seg, tab-sem-3dovs, the removal figure): GaussianDS
# against each method at its defaults. tab-rec-main prints no mean, so its row is the bench scene, the
# scene of the ablation tables; tab-seg and tab-sem-3dovs print an overall mean, which their rows take.
_REC = "Sec. Multi-view 3D Reconstruction, Table tab-rec-main (bench)"
_SEG = "Sec. Open-Vocabulary 3D Semantic Segmentation, Table tab-seg (overall)"
_BOUNDARY = "Sec. Boundary-Aware Semantic Segmentation, Table tab-sem-3dovs (overall)"
_REMOVAL = "Sec. Object Removal, Fig. fig-objectremoval"
FPS_MARGIN = math.log(1.25)   # "comparable" FPS: the ratio within 0.80 to 1.25, gsbench's margin, not the paper's
_GDS = {"method": "gaussiands"}
_BASELINE_NAMES = {"vanilla": "vanilla 3DGS", "grouping": "Gaussian Grouping",
                   "twostage": "the LangSplat-style twostage"}


def _versus(key: str, metric: str, base: str, source: str, sign: int, ours: float | None, theirs: float | None,
            unit: str, decimals: int = PAPER_DECIMALS, label: str = "") -> Claim:
    """GaussianDS against one method at its defaults on one metric (the paper's two printed values)."""
    word = "beats" if metric not in ("lpips", "removal_residual") else "has a lower " + (label or metric) + " than"
    text = (f"GaussianDS beats {_BASELINE_NAMES[base]} in {label or metric}" if word == "beats"
            else f"GaussianDS {word} {_BASELINE_NAMES[base]}")
    paper = gap(ours, theirs, decimals) if ours is not None and theirs is not None else None
    note = (f"{ours:.{decimals}f} vs {theirs:.{decimals}f} {unit}".rstrip() if paper is not None else unit)
    return Claim(key, text, source, metric, sign, paper, note, dict(_GDS), {"method": base},
                 paper_decimals=decimals)


def _headline_claims() -> tuple[Claim, ...]:
    """The headline rows: reconstruction against vanilla and Grouping (bench), FPS against vanilla,
    segmentation against twostage and Grouping (overall means), removal against Grouping (figure only)."""
    rec = [_versus(f"rec_{m}_{base}", m, base, _REC, sign, ours, theirs, "dB" if m == "psnr" else "", label=m.upper())
           for base, vals in (("vanilla", (24.81, 16.02, 0.72, 0.42, 0.15, 0.50)),
                              ("grouping", (24.81, 18.71, 0.72, 0.53, 0.15, 0.42)))
           for m, sign, ours, theirs in (("psnr", +1, vals[0], vals[1]), ("ssim", +1, vals[2], vals[3]),
                                         ("lpips", -1, vals[4], vals[5]))]
    fps = Claim("rec_fps_vanilla", "GaussianDS renders at an FPS comparable to vanilla 3DGS", _REC, "fps", 0, None,
                "~190 vs ~195 FPS, ratio 0.97: 'comparable'; gsbench margin: a ratio of 0.80 to 1.25",
                dict(_GDS), {"method": "vanilla"}, margin=FPS_MARGIN, log_ratio=True,
                unguarded="a timing on the machine that ran the cells, which no mechanism switches off")
    seg = [_versus("seg_lerf_twostage", "miou_lerf", "twostage", _SEG, +1, 60.5, 51.4, "%, LangSplat", 1,
                   "LERF mIoU"),
           _versus("seg_lerf_grouping", "miou_lerf", "grouping", _SEG, +1, 60.5, 36.6, "%, GS-Grouping", 1,
                   "LERF mIoU"),
           _versus("seg_3dovs_miou_twostage", "miou", "twostage", _BOUNDARY, +1, 97.79, 94.60, "%, LangSplatV2",
                   label="3D-OVS mIoU"),
           _versus("seg_3dovs_mbiou_twostage", "mbiou", "twostage", _BOUNDARY, +1, 90.28, 88.40, "%, LangSplatV2",
                   label="3D-OVS mBIoU"),
           _versus("seg_3dovs_miou_grouping", "miou", "grouping", _BOUNDARY, +1, None, None,
                   "Gaussian Grouping is not in the table", label="3D-OVS mIoU"),
           _versus("seg_3dovs_mbiou_grouping", "mbiou", "grouping", _BOUNDARY, +1, None, None,
                   "Gaussian Grouping is not in the table", label="3D-OVS mBIoU")]
    removal = _versus("removal_grouping", "removal_residual", "grouping", _REMOVAL, -1, None, None,
                      "figure only, no number", label="removal residual")
    return (*rec, fps, *seg, removal)
_NO_DEPTH = {AX_LAMBDAS[0]: 0.0}


def _formulation(key: str, text: str, metric: str, row: str, ref: str, a: float, b: float, unit: str) -> Claim:
    return Claim(key, text, _DEPTH_ALIGN, metric, +1, gap(a, b), f"{a:.2f} vs {b:.2f} {unit}",
                 {AX_FORMULATION: row}, {AX_FORMULATION: ref})


# The studies, in the running order of the claims plan (paper studies, then the controls).
DECLARED: tuple[Study, ...] = (
    Study("reconstruction", "Reconstruction and segmentation per scene (Tables I-III)", ("method",),
          {"method": "gaussiands"}, "GaussianDS (the paper's method) on the same scene", main=True,
          claims_grids=("headline-cpu", "headline-fewview-cpu", "headline-real-cpu"), claims=_headline_claims()),
    Study("ordering", "Pseudo-video ordering", ("priors.ordering",), {"priors.ordering": "pose"},
          "pose-nearest ordering (the paper's method)", claims_grids=("ordering-cpu", "ordering-fewview-cpu",
                                                                      "ordering-real-cpu"), claims=(
              Claim("ordering_pose_random", "pose-nearest ordering raises adjacent mask IoU over random", _ORDER_TAB,
                    "ordering_adjacent_mask_iou_strict", +1, gap(53.21, 33.92), "53.21 vs 33.92 %",
                    {AX_ORDERING: "pose"}, {AX_ORDERING: "random"}),
              Claim("ordering_pose_filename", "pose-nearest ordering raises adjacent mask IoU over filename order",
                    _ORDER_TAB, "ordering_adjacent_mask_iou_strict", +1, gap(53.21, 50.85), "53.21 vs 50.85 %",
                    {AX_ORDERING: "pose"}, {AX_ORDERING: "filename"}))),
    Study("depth_formulation", "Depth supervision formulation", ("gaussiands.depth_formulation",),
          {"gaussiands.depth_formulation": "scale_shift"}, "scale-shift aligned depth (the paper's method)",
          claims_grids=("depth_formulation-cpu", "depth_formulation-fewview-cpu",
                        "depth_formulation-real-cpu"), claims=(
              _formulation("depth_ss_raw_psnr", "scale-shift beats raw L1 depth (PSNR)", "psnr", "scale_shift",
                           "raw_l1", 24.81, 21.31, "dB"),
              _formulation("depth_mm_raw_psnr", "min-max beats raw L1 depth (PSNR)", "psnr", "minmax", "raw_l1",
                           23.93, 21.31, "dB"),
              _formulation("depth_ss_mm_psnr", "scale-shift beats min-max depth (PSNR)", "psnr", "scale_shift",
                           "minmax", 24.81, 23.93, "dB"),
              _formulation("depth_ss_raw_mbiou", "scale-shift beats raw L1 depth (mBIoU)", "mbiou", "scale_shift",
                           "raw_l1", 91.99, 59.69, "%"),
              _formulation("depth_ss_mm_mbiou", "scale-shift beats min-max depth (mBIoU)", "mbiou", "scale_shift",
                           "minmax", 91.99, 89.21, "%"))),
    Study("loss_subsets", "Loss subsets", _LOSSES, {k: True for k in _LOSSES},
          "all three losses on (the paper's full objective)",
          claims_grids=("loss_subsets-cpu", "loss_subsets-fewview-cpu", "loss_subsets-real-cpu"), claims=(
              Claim("loss_depth_psnr", "L_depth alone raises PSNR over no auxiliary loss", _TAB_ABL, "psnr", +1,
                    gap(22.46, 16.02), "22.46 vs 16.02 dB", {**_NONE, AX_LOSSES[0]: True}, _NONE),
              Claim("loss_ds_miou", "L_ds alone raises mIoU over no auxiliary loss", _TAB_ABL, "miou", +1,
                    gap(84.40, 47.10), "84.40 vs 47.10 %", {**_NONE, AX_LOSSES[2]: True}, _NONE, inputs=DS_INPUTS),
              Claim("loss_all_psnr", "all three losses raise PSNR over none", _TAB_ABL, "psnr", +1,
                    gap(24.81, 16.02), "24.81 vs 16.02 dB", _ALL, _NONE),
              Claim("loss_all_miou", "all three losses raise mIoU over none", _TAB_ABL, "miou", +1,
                    gap(96.97, 47.10), "96.97 vs 47.10 %", _ALL, _NONE),
              Claim("loss_ds_mbiou", "adding L_ds to L_depth + L_tv raises mBIoU (boundary leakage)",
                    f"{_ABL} (loss decomposition) and Sec. Boundary-Aware Semantic Segmentation", "mbiou", +1,
                    None, "no number given", _ALL, {**_ALL, AX_LOSSES[2]: False}, inputs=DS_INPUTS))),
    Study("lambda_grid", "Lambda grid (hyper-parameter sensitivity)", _LAMBDAS,
          claims_grids=("lambda_grid-cpu", "lambda_grid-fewview-cpu", "lambda_grid-real-cpu"), claims=(
              Claim("lambda_depth_r", "lambda_depth correlates negatively with mIoU", _SWEEP, "miou", -1, -0.89,
                    "Pearson r", correlation="axis.gaussiands.lambdas.depth"),
              Claim("lambda_sem_r", "lambda_sem correlates positively with mIoU", _SWEEP, "miou", +1, 0.69,
                    "Pearson r", correlation="axis.gaussiands.lambdas.sem"))),
    Study("latent_dim", "Latent dimension d", ("semantic.latent_dim", "method"),
          {"method": "gaussiands", "semantic.latent_dim": 3}, "d = 3 (the paper's default)",
          claims_grids=("latent_dim-cpu", "latent_dim-fewview-cpu", "latent_dim-real-cpu"), claims=(
              Claim("latent_16_3", "mIoU rises from d = 3 to d = 16", _DIMS, "miou", +1, gap(_D[16], _D[3]),
                    f"{_D[16]:.2f} vs {_D[3]:.2f} %",
                    {"method": "gaussiands", AX_LATENT: 16}, {"method": "gaussiands", AX_LATENT: 3}),
              Claim("latent_32_16", "mIoU falls from d = 16 to d = 32", _DIMS, "miou", -1, gap(_D[32], _D[16]),
                    f"{_D[32]:.2f} vs {_D[16]:.2f} %",
                    {"method": "gaussiands", AX_LATENT: 32}, {"method": "gaussiands", AX_LATENT: 16}))),
    Study("depth_noise", "Depth-noise robustness", _NOISE, {_NOISE[0]: None, _NOISE[1]: 0},
          "the clean depth prior (severity 0)", claims_grids=("depth_noise-cpu", "depth_noise-fewview-cpu",
                                                                       "depth_noise-real-cpu"), claims=(
              Claim("noise_motion_blur", "motion blur on the depth prior lowers PSNR (the most of the four kinds)",
                    _FIG_NOISE, "psnr", -1, None, "figure only, no number",
                    {AX_NOISE_TYPE: "motion_blur", AX_NOISE_SEVERITY: MAX}, _NOISE_CLEAN),
              *[Claim(f"noise_{kind}", f"PSNR is robust to {kind.replace('_', '-')} noise on the depth prior",
                      _FIG_NOISE, "psnr", 0, None,
                      f"figure only: 'remarkably robust'; gsbench margin +-{ROBUST_MARGIN_DB} dB",
                      {AX_NOISE_TYPE: kind, AX_NOISE_SEVERITY: MAX}, _NOISE_CLEAN)
                for kind in ("gaussian", "poisson", "salt_pepper")])),
    # the guard is the 3-view rows, where the references find the depth term's gain; the 6- and 9-view
    # rows show it shrink (their own Holm family, guarding nothing), so they cannot dilute the guard
    Study("control_depth", "Control: few-view L_depth with an exact prior", ("train.views", "gaussiands.lambdas.depth"),
          kind="control", claims_grids=("control_depth-cpu",), controls=(
              Control("depth_psnr", "3 views: L_depth with an exact prior raises held-out PSNR", "psnr", +1, _FEW,
                      _NO_DEPTH, _DEPTH_CLAIMS, where={AX_VIEWS: (3,)}),
              Control("depth_error", "3 views: L_depth with an exact prior lowers the depth error on covered pixels",
                      "depth_absrel_covered", -1, _FEW, _NO_DEPTH, where={AX_VIEWS: (3,)}),
              Control("depth_psnr_more_views", "6 and 9 views: the PSNR gain of L_depth (expected to shrink)",
                      "psnr", +1, _FEW, _NO_DEPTH, where={AX_VIEWS: (6, 9)}),
              Control("depth_error_more_views", "6 and 9 views: the covered-pixel depth error under L_depth",
                      "depth_absrel_covered", -1, _FEW, _NO_DEPTH, where={AX_VIEWS: (6, 9)}))),
    # does the noise reach the geometry at all? The same runs, the rendered-depth error; it guards nothing:
    # the depth-noise claims are about PSNR, so only the PSNR control can un-blind them
    Study("control_depth_noise", "Control: depth noise at lambda_depth 1, few views", _NOISE, kind="control",
          claims_grids=("control_depth_noise-cpu",), controls=(
              Control("depth_noise", "few views, lambda_depth 1: noise on the depth prior lowers PSNR", "psnr", -1,
                      (AX_NOISE_TYPE, AX_NOISE_SEVERITY), _NOISE_CLEAN,
                      ("noise_motion_blur", "noise_gaussian", "noise_poisson", "noise_salt_pepper")),
              Control("depth_noise_error", "few views, lambda_depth 1: noise on the depth prior raises the depth "
                      "error on covered pixels", "depth_absrel_covered", +1, (AX_NOISE_TYPE, AX_NOISE_SEVERITY),
                      _NOISE_CLEAN))),
    Study("control_ds", "Control: edge-averaged L_ds with capped Gaussians", ("gaussiands.losses.ds",),
          kind="control", claims_grids=("control_ds-cpu",), controls=(
              Control("ds_mbiou", "capped Gaussians, edge-averaged L_ds raises mBIoU", "mbiou", +1,
                      (AX_LOSSES[2],), {AX_LOSSES[2]: False},
                      ("loss_ds_miou", "loss_ds_mbiou", "seg_3dovs_mbiou_twostage", "seg_3dovs_mbiou_grouping"),
                      DS_INPUTS),)),
    Study("control_ds_fewview", "Control: edge-averaged L_ds with capped Gaussians at 3 views",
          ("gaussiands.losses.ds",), kind="control", claims_grids=("control_ds_fewview-cpu",), controls=(
              Control("ds_mbiou_fewview", "3 views, capped Gaussians: edge-averaged L_ds raises mBIoU", "mbiou", +1,
                      (AX_LOSSES[2],), {AX_LOSSES[2]: False},
                      ("loss_ds_miou", "loss_ds_mbiou", "seg_3dovs_mbiou_twostage", "seg_3dovs_mbiou_grouping"),
                      DS_INPUTS),)),
    # the real capture's own controls, in the capture's regime: it has no exact depth, so the L_depth control
    # takes the claims' own prior; each is its own Holm family, so it neither dilutes nor borrows the synthetic ones
    Study("control_depth_real", "Control: L_depth on the real capture", ("gaussiands.lambdas.depth",), kind="control",
          claims_grids=("control_depth_real-cpu",), controls=(
              Control("depth_psnr_real", "the capture: L_depth with the capture's own prior raises held-out PSNR",
                      "psnr", +1, (AX_LAMBDAS[0],), _NO_DEPTH, _DEPTH_CLAIMS),)),
    Study("control_ds_real", "Control: edge-averaged L_ds with capped Gaussians on the real capture",
          ("gaussiands.losses.ds",), kind="control", claims_grids=("control_ds_real-cpu",), controls=(
              Control("ds_mbiou_real", "the capture, capped Gaussians: edge-averaged L_ds raises mBIoU", "mbiou", +1,
                      (AX_LOSSES[2],), {AX_LOSSES[2]: False},
                      ("loss_ds_miou", "loss_ds_mbiou", "seg_3dovs_mbiou_twostage", "seg_3dovs_mbiou_grouping"),
                      DS_INPUTS),)),
    Study("control_latent", "Control: latent d on a 14-class scene", ("semantic.latent_dim",), kind="control",
          claims_grids=("control_latent-cpu",), controls=(
              Control("latent_miou", "14 classes: a larger latent d raises mIoU over d = 1", "miou", +1,
                      (AX_LATENT,), {AX_LATENT: 1}, ("latent_16_3", "latent_32_16")),)),
    Study("control_sem", "Control: lambda_sem 0 against 5", ("gaussiands.lambdas.sem",), kind="control",
          claims_grids=("control_sem-cpu",), controls=(
              Control("sem_miou", "lambda_sem = 5 against 0: the semantic loss raises mIoU (0 collapses)", "miou",
                      +1, (AX_LAMBDAS[2],), {AX_LAMBDAS[2]: 0.0},
                      ("lambda_sem_r", "seg_lerf_twostage", "seg_lerf_grouping", "seg_3dovs_miou_twostage",
                       "seg_3dovs_miou_grouping")),)),
    Study("tiny-test", "Smoke grid (latent d x L_ds)", ("semantic.latent_dim", "gaussiands.losses.ds"),
          {"semantic.latent_dim": 3, "gaussiands.losses.ds": True}, "d = 3 with L_ds on (the defaults)",
          kind="smoke"),
)

# The claims page lists the claims study by study in the paper's order (its main tables, then its ablation
# section); a study not named here follows them, in the order of DECLARED.
CLAIMS_ORDER: tuple[str, ...] = ("reconstruction", "depth_formulation", "loss_subsets", "ordering", "lambda_grid",
                                 "latent_dim", "depth_noise")

# The claims page's claim x regime matrix: its columns, in order. Adding a regime to the page is one entry
# here; its claim and control grids go into the studies' claims_grids when they are run.
REGIMES: tuple[DeclaredRegime, ...] = (
    DeclaredRegime("dense synthetic", "synthetic",
                   Regime("tabletop-medium-0", None, "cpu-medium", "gt", 1.0, "simulated", "text-aligned"),
                   "the claim grids today: tabletop-medium, all 21 training views, default priors"),
    DeclaredRegime("few-view synthetic", "synthetic",
                   Regime("tabletop-medium-0-v24", 3, "cpu-medium", "gt", 1.0, "gt", "text-aligned"),
                   "the 3 training views at which control_depth marks, the depth prior at its default distortion, "
                   "the GT labels as masks (the controls' masks)"),
    DeclaredRegime("real capture", "real",
                   Regime("dtu_scan37", None, "cpu-real", "sfm", None, "gt", "text-aligned"),
                   "dtu_scan37 at cpu-real, the weight-free sfm depth prior, its labels as masks"),
)


# ----------------------------------------------------------------------------- what the consumers read
def studies() -> dict[str, Study]:
    """Every declared study by name, in the order of DECLARED."""
    return {s.name: s for s in DECLARED}


def paper_claims() -> list[Claim]:
    """Every claim, study by study in CLAIMS_ORDER (the others after, as declared), each naming its study."""
    rank = {name: i for i, name in enumerate(CLAIMS_ORDER)}
    ordered = sorted(DECLARED, key=lambda s: rank.get(s.name, len(rank)))
    return [c for s in ordered for c in s.declared_claims()]


def controls() -> list[Control]:
    """Every positive control, in the order of DECLARED, each naming its study."""
    return [c for s in DECLARED for c in s.declared_controls()]


def claim_grids() -> tuple[str, ...]:
    """The grids of the paper studies' claims, in running order."""
    return tuple(g for s in DECLARED if s.kind == "paper" for g in s.claims_grids)


def control_grids() -> tuple[str, ...]:
    """The grids of the positive controls, in running order."""
    return tuple(g for s in DECLARED if s.kind == "control" for g in s.claims_grids)


def main_studies() -> tuple[Optional[str], ...]:
    """The runs that feed the main tables: standalone runs (no study) and the main studies."""
    return (None, *(s.name for s in DECLARED if s.main))


# the shipped table as constants, for readers that need no declaration added later
STUDIES: dict[str, Study] = studies()
MAIN_STUDIES: tuple[Optional[str], ...] = main_studies()
PAPER_CLAIMS: list[Claim] = paper_claims()
CONTROLS: list[Control] = controls()

__all__ = ["Study", "Claim", "Control", "Regime", "DeclaredRegime", "DECLARED", "CLAIMS_ORDER", "REGIMES",
           "STUDIES", "MAIN_STUDIES", "PAPER_CLAIMS", "CONTROLS", "ROBUST_MARGIN_DB", "MAX", "LATENT_DIM_MIOU",
           "DS_INPUTS", "column", "studies", "paper_claims", "controls", "claim_grids", "control_grids",
           "main_studies", "AX_ORDERING", "AX_FORMULATION", "AX_LOSSES", "AX_LATENT", "AX_LAMBDAS",
           "AX_NOISE_TYPE", "AX_NOISE_SEVERITY", "AX_VIEWS"]
