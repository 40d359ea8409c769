"""Dose-response figures of the claims section: for each swept lambda, noise severity and latent d
(the claim studies and their controls), the metric's mean over seeds and its 95 % band against the
swept value, with the paper's value marked (its default setting, or its reported numbers when they
are in the same units).

Why: a verdict is one interval; the curve shows whether the effect grows with the dose, where it
turns, and how wide the seed spread is at each value.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gsbench.methods.gaussiands.study_table import LATENT_DIM_MIOU
from gsbench.reports.data import Results, same
from gsbench.reports.plots import _save, plt

from gsbench.reports.display import (AX_LAMBDAS, AX_LATENT, AX_NOISE_SEVERITY, AX_NOISE_TYPE, AX_VIEWS,  # isort: skip
                                  NOISE_LABELS, metric_spec)
from gsbench.reports.stats import mean_band
from gsbench.reports.studies import PROTOCOL_SHORT, _get, _slug, scene_protocols


@dataclass(frozen=True)
class Dose:
    study: str
    axis: str                          # the swept axis column
    metric: str                        # logical or concrete metric
    label: str                         # x-axis label
    paper_x: float | None = None       # the paper's setting of the axis (vertical line)
    paper_points: tuple = ()           # (x, y) the paper reports, in display units
    paper_note: str = ""
    split: str | None = None           # one curve per value of this column (noise kind)
    log_x: bool = False


_FEW_VIEW_LAMBDA = "λ_depth (few-view control; one curve per train.views)"
DOSES: list[Dose] = [
    Dose("lambda_grid", AX_LAMBDAS[0], "miou", "λ_depth", 0.01, paper_note="paper default λ_depth = 0.01",
         log_x=True),
    Dose("lambda_grid", AX_LAMBDAS[2], "miou", "λ_sem", 5.0, paper_note="paper default λ_sem = 5"),
    Dose("depth_noise", AX_NOISE_SEVERITY, "psnr", "noise severity", split=AX_NOISE_TYPE),
    Dose("latent_dim", AX_LATENT, "miou", "latent dimension d", 3.0, tuple(LATENT_DIM_MIOU.items()),
         "paper (waldo_kitchen): d = 3, 16, 32; default d = 3"),
    Dose("control_depth", AX_LAMBDAS[0], "psnr", _FEW_VIEW_LAMBDA, 0.01, paper_note="paper default λ_depth = 0.01",
         split=AX_VIEWS),
    Dose("control_depth", AX_LAMBDAS[0], "depth_absrel_covered", _FEW_VIEW_LAMBDA, 0.01,
         paper_note="paper default λ_depth = 0.01", split=AX_VIEWS),
    Dose("control_depth_noise", AX_NOISE_SEVERITY, "psnr", "noise severity (few-view control)", split=AX_NOISE_TYPE),
    Dose("control_latent", AX_LATENT, "miou", "latent dimension d (14-class control)", 3.0,
         paper_note="paper default d = 3"),
]


def _curve(res: Results, ids: list[str], axis: str, concrete: str, scale: float) -> list[tuple[float, float, Any, int]]:
    """(x, mean, half-width, n) per distinct value of the axis, over the runs' seeds."""
    by_x: dict[float, list[float]] = {}
    for r in ids:
        x = _get(res, r, axis)
        if x is None or res.runs.at[r, "status"] != "done":
            continue
        v = res.value(r, concrete)
        if math.isfinite(v):
            by_x.setdefault(float(x), []).append(v * scale)
    return [(x, *mean_band(vs), len(vs)) for x, vs in sorted(by_x.items())]


def plot_dose(res: Results, d: Dose, path_prefix: Path) -> list[Path]:
    """One PNG per scene of the dose's study (none when the study or the metric has no value)."""
    ids = res.run_ids(study=d.study)
    out: list[Path] = []
    if not ids or d.axis not in res.runs.columns:
        return out
    sp = metric_spec(d.metric)
    for sc, pr in scene_protocols(res, ids):
        concrete = res.resolve(d.metric, pr)
        if concrete is None:
            continue
        sids = [r for r in ids if res.runs.at[r, "scene"] == sc and same(res.runs.at[r, "protocol"], pr)]
        groups: dict[str, list[str]] = {"": sids}
        if d.split:
            kinds = sorted({str(_get(res, r, d.split)) for r in sids if _get(res, r, d.split) is not None})
            clean = [r for r in sids if _get(res, r, d.split) is None]     # the severity-0 reference
            groups = {k: [r for r in sids if str(_get(res, r, d.split)) == k] + clean for k in kinds}
        curves = {k: _curve(res, g, d.axis, concrete, sp.scale) for k, g in groups.items()}
        curves = {k: c for k, c in curves.items() if c}
        if not curves:
            continue
        fig, ax = plt.subplots(figsize=(6.0, 4.0))
        for k, c in curves.items():
            xs, ms = [p[0] for p in c], [p[1] for p in c]
            lo = [m - (h or 0.0) for _, m, h, _ in c]
            hi = [m + (h or 0.0) for _, m, h, _ in c]
            lab = NOISE_LABELS.get(k, k) if k else "gsbench mean"
            line = ax.plot(xs, ms, marker="o", label=f"{lab} (n={min(p[3] for p in c)}-{max(p[3] for p in c)})")[0]
            ax.fill_between(xs, lo, hi, alpha=0.2, color=line.get_color())
        if d.paper_x is not None:
            ax.axvline(d.paper_x, color="k", linestyle="--", linewidth=1, label=d.paper_note or "paper's setting")
        if d.paper_points:
            ax.plot([p[0] for p in d.paper_points], [p[1] for p in d.paper_points], "kx", markersize=8,
                    label=d.paper_note or "paper")
        if d.log_x and all(p[0] > 0 for c in curves.values() for p in c):
            ax.set_xscale("log")
        ax.set_xlabel(d.label)
        ax.set_ylabel(sp.label)
        ax.set_title(f"{d.study}: {sp.label} vs {d.label}\n{sc} ({PROTOCOL_SHORT.get(pr, pr)}); band = 95 % interval "
                     "of the mean over seeds", fontsize=9)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
        name = f"{path_prefix.name}_{_slug(d.study)}_{_slug(d.axis.rsplit('.', 1)[-1])}_{_slug(d.metric)}_{_slug(sc)}"
        out.append(_save(fig, path_prefix.parent / f"{name}.png"))
    return out


def plot_doses(res: Results, path_prefix: Path) -> list[Path]:
    """Every dose-response figure that has data."""
    out: list[Path] = []
    for d in DOSES:
        out += plot_dose(res, d, path_prefix)
    return out
