"""The one table of metrics: every name a results.json may hold (with the segmentation names built by
`seg_metric`), and how each is shown: label, LaTeX header, which direction is better, display scale
and decimals. results.py writes and checks these names, collect reads them, the report shows them.

Why here (ground floor): the writer (gsbench.results), the reader (gsbench.collect) and the report
(gsbench.reports) all import this module, so a name and its spec cannot drift apart. The
implementation id of each value (which code and convention computed it) is recorded per run in
results.json `metric_impl`, by the metric functions themselves.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from gsbench.config_keys import QUERY_MODES

FRAME_SETS = ("reference", "held-out")
FRAME_SET_SUFFIX = {"reference": "", "held-out": "_heldout"}

# ssim / lpips: the 3DGS forms (zero-padded SSIM, LPIPS on [0, 1] inputs) that 3DGS-family papers report;
# ssim_valid / lpips_package: the valid-region SSIM and the LPIPS package's [-1, 1] input convention.
IMAGE_METRICS = ("psnr", "ssim", "lpips", "fps", "ssim_valid", "lpips_package")
SEG_BASES = {"3dovs": ("miou", "mbiou", "pixel_acc", "pixel_acc_labelled"), "lerf": ("miou", "loc_acc")}
MASK_FOLDER_METRICS = ("mbiou_lerf",)
REMOVAL_METRICS = ("removal_residual", "removal_psnr_outside")
# depth_absrel counts an empty pixel as an error of 1; the covered-pixel error and the coverage beside it
# tell a wrong depth from a missing surface (gsbench/evaluation/depth.py)
DEPTH_METRICS = ("depth_absrel", "depth_absrel_covered", "depth_coverage")
# the 3d-points protocol: labelled surface points of a synthetic scene classed through their nearest Gaussian
# (gsbench/evaluation/points3d.py); mIoU and mAcc over the classes present among the points
POINTS3D_METRICS = ("miou_3d", "macc_3d")
ORDERING_METRICS = ("ordering_adjacent_distance", "ordering_adjacent_mask_iou", "ordering_adjacent_mask_iou_strict",
                    "ordering_adjacent_mask_iou_flow")
# what the method was given to work with, read from its train summary: the share of pixels the L_ds edge
# map marks (a study of L_ds says nothing when it is near 0; docs/methods.md)
INPUT_METRICS = ("ds_edge_fraction",)
TIMING_NAMES = ("train_s", "eval_s", "render_ms")
MEMORY_NAMES = ("peak_rss_mb", "train_peak_rss_mb", "peak_cuda_mb", "train_peak_cuda_mb", "eval_peak_cuda_mb")


# protocol name -> its key in metric names, where they differ (e.g. "3d-points": "3d")
SEG_KEYS: dict[str, str] = {}


def seg_metric(base: str, protocol: str, mode: Optional[str] = None, frame_set: str = "reference") -> str:
    """Name of a segmentation metric, e.g. ("miou", "lerf", "decode", "held-out") -> miou_lerf_decode_heldout."""
    if protocol not in SEG_BASES or base not in SEG_BASES[protocol]:
        raise ValueError(f"no segmentation metric {base!r} for protocol {protocol!r}")
    if mode is not None and mode not in QUERY_MODES:
        raise ValueError(f"query mode must be one of {QUERY_MODES}, got {mode!r}")
    return f"{base}_{SEG_KEYS.get(protocol, protocol)}" + (f"_{mode}" if mode else "") + FRAME_SET_SUFFIX[frame_set]


def _seg_names() -> tuple[str, ...]:
    return tuple(seg_metric(b, p, m, f) for p, bases in SEG_BASES.items() for b in bases
                 for m in (None, *QUERY_MODES) for f in FRAME_SETS)


#: every name `metrics` may hold, in report order
METRIC_NAMES: tuple[str, ...] = (IMAGE_METRICS + _seg_names() + MASK_FOLDER_METRICS + REMOVAL_METRICS
                                 + ORDERING_METRICS + DEPTH_METRICS + INPUT_METRICS + POINTS3D_METRICS)
#: every quantity a collected row may carry (metrics, timings, memory); a registered protocol adds its names
#: (`add_segmentation_protocol`)
KNOWN_METRICS: set[str] = set(METRIC_NAMES + TIMING_NAMES + MEMORY_NAMES)


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
    "depth_absrel_covered": MetricSpec("Depth AbsRel, covered px (%)", "Depth AbsRel covered (\\%)", "lower",
                                       100.0, 2),
    "depth_coverage": _pct("Depth coverage"),
    "miou_3d": _pct("3D mIoU"),
    "macc_3d": _pct("3D mAcc"),
    "ordering_adjacent_distance": MetricSpec("Adjacent pose distance", "Adjacent Pose Distance", "lower", 1.0, 3),
    "ordering_adjacent_mask_iou": _pct("Adjacent mask IoU (shared ids)"),
    "ordering_adjacent_mask_iou_strict": _pct("Adjacent mask IoU (strict)"),
    "ordering_adjacent_mask_iou_flow": _pct("Adjacent mask IoU (strict, flow)"),
    "ds_edge_fraction": MetricSpec("L_ds edge pixels (%)", "$E_d$ pixels (\\%)", None, 100.0, 3),
    # timings / memory (rows of the long table with source "timings" / "memory")
    "train_s": MetricSpec("Training time (min)", "Training Time (min)", "lower", 1.0 / 60.0, 2),
    "eval_s": MetricSpec("Eval time (s)", "Eval Time (s)", "lower", 1.0, 1),
    "render_ms": MetricSpec("Render time (ms)", "Render Time (ms)", "lower", 1.0, 2),
    "peak_rss_mb": MetricSpec("Peak RSS memory (MB)", "Peak RSS (MB)", "lower", 1.0, 0),
    "train_peak_rss_mb": MetricSpec("Peak RSS memory (MB)", "Peak RSS (MB)", "lower", 1.0, 0),
    "peak_cuda_mb": MetricSpec("Peak CUDA memory (MB)", "Peak VRAM (MB)", "lower", 1.0, 0),
    "train_peak_cuda_mb": MetricSpec("Peak CUDA memory (MB)", "Peak VRAM (MB)", "lower", 1.0, 0),
}


_SEG_LABEL = {"miou": "mIoU", "mbiou": "mBIoU", "pixel_acc": "Pixel acc.",
              "pixel_acc_labelled": "Pixel acc. (labelled)", "loc_acc": "Loc. acc."}
for _p, _bases in SEG_BASES.items():      # every segmentation name: the base's label, its mode, its frame set
    for _b in _bases:
        for _m in (None, *QUERY_MODES):
            for _f in FRAME_SETS:
                _name = seg_metric(_b, _p, _m, _f)
                _label = _SEG_LABEL[_b] + (f" {_m}" if _m else "") + (" held-out" if _f == "held-out" else "")
                METRICS.setdefault(_name, _pct(_label))
METRICS.setdefault("mbiou_lerf", _pct("mBIoU"))
METRICS.setdefault("eval_peak_cuda_mb", MetricSpec("Peak CUDA memory, eval (MB)", "Peak VRAM eval (MB)", "lower",
                                                   1.0, 0))


def add_segmentation_protocol(protocol: str, key: str, bases: tuple[str, ...]) -> None:
    """Enter a protocol's metric names (its bases x query modes x frame sets) in this table: the hook the
    evaluation's protocol registry calls, so a protocol added as one file (or a plugin's) writes names
    that results.json accepts. A protocol already here must declare the same bases."""
    if protocol in SEG_BASES:
        if tuple(SEG_BASES[protocol]) != tuple(bases) or SEG_KEYS.get(protocol, protocol) != key:
            raise ValueError(f"protocol {protocol!r} declares metrics {tuple(bases)} under {key!r}; the metric "
                             f"table has {tuple(SEG_BASES[protocol])} under {SEG_KEYS.get(protocol, protocol)!r}")
        return
    taken = {SEG_KEYS.get(p, p) for p in SEG_BASES}
    if key in taken or not key.replace("_", "").isalnum():
        raise ValueError(f"protocol {protocol!r}: metric key {key!r} is taken or not letters, digits and '_'")
    SEG_BASES[protocol] = tuple(bases)
    if key != protocol:
        SEG_KEYS[protocol] = key
    for b in bases:
        for m in (None, *QUERY_MODES):
            for f in FRAME_SETS:
                name = seg_metric(b, protocol, m, f)
                label = _SEG_LABEL.get(b, b) + (f" {m}" if m else "") + (" held-out" if f == "held-out" else "")
                METRICS.setdefault(name, _pct(label))
                KNOWN_METRICS.add(name)


LOGICAL_SPEC = {
    "miou": _pct("mIoU"),
    "mbiou": _pct("mBIoU"),
}


__all__ = ["MetricSpec", "METRICS", "LOGICAL_SPEC", "METRIC_NAMES", "KNOWN_METRICS", "SEG_BASES", "FRAME_SETS",
           "FRAME_SET_SUFFIX", "IMAGE_METRICS", "MASK_FOLDER_METRICS", "REMOVAL_METRICS", "DEPTH_METRICS",
           "ORDERING_METRICS", "INPUT_METRICS", "POINTS3D_METRICS", "TIMING_NAMES", "MEMORY_NAMES", "seg_metric",
           "SEG_KEYS", "add_segmentation_protocol"]
