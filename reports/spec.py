"""What the report knows about metrics and studies: display names, units, which direction is
better, how many decimals. One place, so tables, plots and the HTML agree.

Metric names and study / axis keys are the ones defined in gsbench/store.py.
"""
from __future__ import annotations

from dataclasses import dataclass

from gsbench.method_table import METHODS, get_spec


@dataclass(frozen=True)
class MetricSpec:
    label: str            # plain text (Markdown / HTML / plots)
    latex: str            # LaTeX header text
    better: str | None    # "higher" | "lower" | None (no best marked)
    scale: float = 1.0    # display value = stored value * scale (fractions shown as %)
    decimals: int = 2


def _pct(label: str, better: str = "higher") -> MetricSpec:
    return MetricSpec(f"{label} (%)", f"{label} (\\%)", better, 100.0, 2)


METRICS: dict[str, MetricSpec] = {
    "psnr": MetricSpec("PSNR (dB)", "PSNR (dB)", "higher", 1.0, 2),
    # ssim / lpips are the 3DGS forms (comparable with 3DGS-family papers); the other conventions:
    "ssim": MetricSpec("SSIM", "SSIM", "higher", 1.0, 3),
    "lpips": MetricSpec("LPIPS", "LPIPS", "lower", 1.0, 3),
    "ssim_valid": MetricSpec("SSIM (valid region)", "SSIM (valid)", "higher", 1.0, 3),
    "lpips_package": MetricSpec("LPIPS ([-1, 1] input)", "LPIPS ($[-1,1]$ input)", "lower", 1.0, 3),
    "fps": MetricSpec("FPS", "FPS", "higher", 1.0, 1),
    "miou_3dovs": _pct("mIoU"),
    "mbiou_3dovs": _pct("mBIoU"),
    "pixel_acc_3dovs": _pct("Pixel acc."),
    "miou_3dovs_encode": _pct("mIoU encode"),
    "miou_3dovs_decode": _pct("mIoU decode"),
    "mbiou_3dovs_encode": _pct("mBIoU encode"),
    "mbiou_3dovs_decode": _pct("mBIoU decode"),
    "miou_lerf": _pct("mIoU"),
    "loc_acc_lerf": _pct("Loc. acc."),
    "miou_lerf_encode": _pct("mIoU encode"),
    "miou_lerf_decode": _pct("mIoU decode"),
    "removal_residual": MetricSpec("Residual object px (%)", "Residual object px (\\%)", "lower", 100.0, 2),
    "removal_psnr_outside": MetricSpec("PSNR outside (dB)", "PSNR outside (dB)", "higher", 1.0, 2),
    "depth_absrel": MetricSpec("Depth AbsRel (%)", "Depth AbsRel (\\%)", "lower", 100.0, 2),
    "ordering_adjacent_distance": MetricSpec("Adjacent pose distance", "Adjacent Pose Distance", "lower", 1.0, 3),
    "ordering_adjacent_mask_iou": _pct("Adjacent mask IoU (shared ids)"),
    "ordering_adjacent_mask_iou_strict": _pct("Adjacent mask IoU (strict)"),
    "ordering_adjacent_mask_iou_flow": _pct("Adjacent mask IoU (strict, flow)"),
    # timings / memory (rows of the long table with source "timings" / "memory")
    "train_s": MetricSpec("Training time (min)", "Training Time (min)", "lower", 1.0 / 60.0, 2),
    "eval_s": MetricSpec("Eval time (s)", "Eval Time (s)", "lower", 1.0, 1),
    "render_ms": MetricSpec("Render time (ms)", "Render Time (ms)", "lower", 1.0, 2),
    "peak_rss_mb": MetricSpec("Peak RSS memory (MB)", "Peak RSS (MB)", "lower", 1.0, 0),
    "train_peak_rss_mb": MetricSpec("Peak RSS memory (MB)", "Peak RSS (MB)", "lower", 1.0, 0),
    "peak_cuda_mb": MetricSpec("Peak CUDA memory (MB)", "Peak VRAM (MB)", "lower", 1.0, 0),
    "train_peak_cuda_mb": MetricSpec("Peak CUDA memory (MB)", "Peak VRAM (MB)", "lower", 1.0, 0),
}
KNOWN_METRICS = set(METRICS)

# Logical metric -> concrete metric name per protocol ("mIoU" of a 3D-OVS scene is miou_3dovs).
LOGICAL = {
    "miou": {"3dovs": "miou_3dovs", "lerf": "miou_lerf"},
    "mbiou": {"3dovs": "mbiou_3dovs"},
}
LOGICAL_SPEC = {
    "miou": _pct("mIoU"),
    "mbiou": _pct("mBIoU"),
}

PROTOCOL_LABELS = {"3dovs": "3D-OVS protocol", "lerf": "LERF-OVS protocol", None: "no semantic protocol"}

STUDIES = {
    "reconstruction": "Reconstruction and segmentation per scene (Tables I-III)",
    "ordering": "Pseudo-video ordering",
    "depth_formulation": "Depth supervision formulation",
    "loss_subsets": "Loss subsets",
    "latent_dim": "Latent dimension d",
    "lambda_grid": "Lambda grid (hyper-parameter sensitivity)",
    "depth_noise": "Depth-noise robustness",
}

AX_ORDERING = "axis.priors.ordering"
AX_FORMULATION = "axis.gaussiands.depth_formulation"
AX_LOSSES = ["axis.gaussiands.losses.depth", "axis.gaussiands.losses.tv", "axis.gaussiands.losses.ds"]
AX_LATENT = "axis.gaussiands.latent_dim"
AX_LAMBDAS = ["axis.gaussiands.lambdas.depth", "axis.gaussiands.lambdas.tv",
              "axis.gaussiands.lambdas.sem", "axis.gaussiands.lambdas.ds"]
AX_NOISE_TYPE = "axis.priors.depth.noise.type"
AX_NOISE_SEVERITY = "axis.priors.depth.noise.severity"

ORDERING_LABELS = {"random": "Random", "filename": "Filename order", "pose": "Pose-nearest"}
ORDERING_ORDER = ["random", "filename", "pose"]
FORMULATION_LABELS = {
    "none": "No depth loss", "raw_l1": "Raw L1 supervision", "minmax": "Min-max normalized depth",
    "scale_shift": "Scale-shift aligned depth", "pearson": "Pearson correlation",
}
FORMULATION_ORDER = ["none", "raw_l1", "minmax", "scale_shift", "pearson"]
NOISE_LABELS = {"gaussian": "Gaussian", "poisson": "Poisson", "motion_blur": "Motion blur",
                "salt_pepper": "Salt-and-pepper"}
NOISE_ORDER = ["gaussian", "poisson", "motion_blur", "salt_pepper"]
# Paper order of the loss subsets (depth, tv, ds); the paper omits (tv, ds), listed here before "all".
LOSS_SUBSET_ORDER = [
    (False, False, False), (True, False, False), (False, True, False), (False, False, True),
    (True, True, False), (True, False, True), (False, True, True), (True, True, True),
]

# The reference row of each study: every other row is compared with it (difference and its 95 %
# interval). The paper's full method or the default setting; a study not listed has no reference.
STUDY_REFERENCE: dict[str, dict] = {
    "reconstruction": {"method": "gaussiands"},
    "ordering": {AX_ORDERING: "pose"},
    "depth_formulation": {AX_FORMULATION: "scale_shift"},
    "loss_subsets": {AX_LOSSES[0]: True, AX_LOSSES[1]: True, AX_LOSSES[2]: True},
    "depth_noise": {AX_NOISE_TYPE: None, AX_NOISE_SEVERITY: 0},
    "latent_dim": {"method": "gaussiands", AX_LATENT: 3},
    "tiny-test": {AX_LATENT: 3, AX_LOSSES[2]: True},
}
REFERENCE_TEXT = {
    "reconstruction": "GaussianDS (the paper's method) on the same scene",
    "ordering": "pose-nearest ordering (the paper's method)",
    "depth_formulation": "scale-shift aligned depth (the paper's method)",
    "loss_subsets": "all three losses on (the paper's full objective)",
    "depth_noise": "the clean depth prior (severity 0)",
    "latent_dim": "d = 3 (the paper's default)",
    "tiny-test": "d = 3 with L_ds on (the defaults)",
}


def method_label(method: str) -> str:
    """The registered method's report label (gsbench.method_table); an unknown name as it is."""
    return get_spec(method).label if method in METHODS else str(method)


def metric_spec(name: str) -> MetricSpec:
    """Spec of a metric; unknown metrics get a neutral spec (no best marked)."""
    if name in METRICS:
        return METRICS[name]
    if name in LOGICAL_SPEC:
        return LOGICAL_SPEC[name]
    return MetricSpec(name, name.replace("_", "\\_"), None, 1.0, 3)
