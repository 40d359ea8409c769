"""Positive controls of the paper-claims table: for each mechanism a setting where its effect must
exist if the implementation is right (the control grids, docs/grids.md). A control is *marked* when
at least one of its rows has a 95 % interval that excludes zero on the expected side. A claim whose
control ran and is not marked, and whose own interval shows no effect (not reproduced, inconclusive),
is "blind" in the claims table: the study could not have seen the mechanism, so its interval says
nothing about the paper's effect.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from gsbench.methods.gaussiands.paper import DS_INPUTS
from gsbench.reports.data import Results, same

from gsbench.reports.spec import (AX_LAMBDAS, AX_LATENT, AX_LOSSES, AX_NOISE_SEVERITY, AX_NOISE_TYPE,  # isort: skip
                                  metric_spec)
from gsbench.reports.stats import compare
from gsbench.reports.studies import PROTOCOL_SHORT, _axis_label, _axis_rank, _get, scene_protocols
from gsbench.reports.table import Cell, Column, Row, Table

MARKED, UNMARKED, OPPOSITE, NOT_RUN = "marked", "unmarked", "opposite", "not run"


@dataclass(frozen=True)
class Control:
    key: str
    text: str
    study: str
    metric: str
    direction: int                 # the side the effect must be on: +1 / -1 (row - reference)
    axes: tuple[str, ...]          # the columns that tell the control's rows apart
    reference: dict                # axis -> value of the reference row
    guards: tuple[str, ...] = ()   # claim keys that are blind when this control is not marked
    inputs: dict = field(default_factory=dict)   # metric -> floor: what a row must have been given


_DEPTH_CLAIMS = ("depth_ss_raw_psnr", "depth_mm_raw_psnr", "depth_ss_mm_psnr", "depth_ss_raw_mbiou",
                 "depth_ss_mm_mbiou", "loss_depth_psnr", "lambda_depth_r")
CONTROLS: list[Control] = [
    Control("depth_psnr", "few views: L_depth with an exact prior raises held-out PSNR", "control_depth", "psnr", +1,
            (AX_LAMBDAS[0],), {AX_LAMBDAS[0]: 0.0}, _DEPTH_CLAIMS),
    Control("depth_error", "few views: L_depth with an exact prior lowers the rendered-depth error", "control_depth",
            "depth_absrel", -1, (AX_LAMBDAS[0],), {AX_LAMBDAS[0]: 0.0}),
    Control("depth_noise", "few views, lambda_depth 1: noise on the depth prior lowers PSNR", "control_depth_noise",
            "psnr", -1, (AX_NOISE_TYPE, AX_NOISE_SEVERITY), {AX_NOISE_TYPE: None, AX_NOISE_SEVERITY: 0},
            ("noise_motion_blur", "noise_gaussian", "noise_poisson", "noise_salt_pepper")),
    Control("ds_mbiou", "capped Gaussians, edge-averaged L_ds raises mBIoU", "control_ds", "mbiou", +1,
            (AX_LOSSES[2],), {AX_LOSSES[2]: False}, ("loss_ds_miou", "loss_ds_mbiou"),
            DS_INPUTS),
    Control("latent_miou", "14 classes: a larger latent d raises mIoU over d = 1", "control_latent", "miou", +1,
            (AX_LATENT,), {AX_LATENT: 1}, ("latent_16_3", "latent_32_16")),
    Control("sem_miou", "lambda_sem = 5 against 0: the semantic loss raises mIoU (0 collapses)", "control_sem",
            "miou", +1, (AX_LAMBDAS[2],), {AX_LAMBDAS[2]: 0.0}, ("lambda_sem_r",)),
]


def starved(res: Results, rids: list[str], inputs: dict) -> str | None:
    """Why the compared row could not show the mechanism: an input metric whose mean over its runs lies
    below the claim's floor (runs without the metric say nothing either way)."""
    for metric, floor in inputs.items():
        vals = [v for v in (res.value(r, metric) for r in rids) if math.isfinite(v)]
        mean = sum(vals) / len(vals) if vals else math.inf
        if mean < floor:
            sp = metric_spec(metric)
            return (f"{sp.label} {sp.scale * mean:.{sp.decimals}f} in the compared row, below "
                    f"{sp.scale * floor:.{sp.decimals}f}")
    return None


def control_rows(res: Results, c: Control) -> list[tuple[str, str, str, str]]:
    """(scene, row label, measured text, mark) per (scene, row) of the control; one 'not run' row
    when its study has no run."""
    ids = res.run_ids(study=c.study)
    if not ids:
        return [("–", "–", "study not run", NOT_RUN)]
    sp = metric_spec(c.metric)
    out = []
    for sc, pr in scene_protocols(res, ids):
        concrete = res.resolve(c.metric, pr)
        sids = [r for r in ids if res.runs.at[r, "scene"] == sc and same(res.runs.at[r, "protocol"], pr)]
        ref = [r for r in sids if all(same(_get(res, r, k), v) for k, v in c.reference.items())]
        combos: list[tuple] = []
        for r in sids:
            t = tuple(_get(res, r, a) for a in c.axes)
            if r not in ref and not any(all(same(x, y) for x, y in zip(t, u)) for u in combos):
                combos.append(t)
        combos.sort(key=lambda t: tuple(_axis_rank(a, v) for a, v in zip(c.axes, t)))
        scene = f"{sc} ({PROTOCOL_SHORT.get(pr, pr)})"
        vb = res.seed_values(ref, concrete, sp.scale) if concrete else {}
        for t in combos:
            label = ", ".join(f"{a.rsplit('.', 1)[-1]}={_axis_label(a, v)}" for a, v in zip(c.axes, t))
            rows = [r for r in sids if all(same(_get(res, r, a), v) for a, v in zip(c.axes, t))]
            va = res.seed_values(rows, concrete, sp.scale) if concrete else {}
            if not va or not vb:
                out.append((scene, label, "n/a (" + ("row" if not va else "reference") + " not run)", NOT_RUN))
                continue
            d = compare(va, vb)
            mde = f"; MDE {d.mde:.{sp.decimals}f}" if d.mde is not None else ""
            if not d.has_interval:
                mark = UNMARKED
            elif (d.lo > 0.0 and c.direction > 0) or (d.hi < 0.0 and c.direction < 0):  # type: ignore[operator]
                mark = MARKED
            elif d.significant:
                mark = OPPOSITE
            else:
                mark = UNMARKED
            why = starved(res, rows, c.inputs)
            out.append((scene, label, d.text(sp.decimals) + mde + (f"; {why}" if why else ""), mark))
    return out


def control_status(res: Results, c: Control) -> str:
    """marked when any row is marked; not run when no row has a measurement; else unmarked / opposite."""
    marks = [m for *_, m in control_rows(res, c)]
    if MARKED in marks:
        return MARKED
    if all(m == NOT_RUN for m in marks):
        return NOT_RUN
    return OPPOSITE if OPPOSITE in marks and UNMARKED not in marks else UNMARKED


def blind_claims(res: Results) -> dict[str, str]:
    """claim key -> the verdict text of a claim whose control ran and is not marked."""
    out: dict[str, str] = {}
    for c in CONTROLS:
        st = control_status(res, c)
        if st in (UNMARKED, OPPOSITE):
            for k in c.guards:
                out.setdefault(k, f"blind: control {c.key} {st}")
    return out


def controls_table(res: Results) -> list[Table]:
    """One row per control and compared setting: the effect against the control's reference row
    with its 95 % interval and MDE, and whether it is marked (no table when no control ran)."""
    if not any(res.run_ids(study=c.study) for c in CONTROLS):
        return []
    rows = []
    for c in CONTROLS:
        ref = ", ".join(f"{k.rsplit('.', 1)[-1]}={_axis_label(k, v)}" for k, v in c.reference.items())
        for scene, label, text, mark in control_rows(res, c):
            rows.append(Row([c.text, f"{c.study} ({metric_spec(c.metric).label})", scene, f"{label} vs {ref}"],
                            [Cell(text=text), Cell(text=mark)]))
    cols = [Column("measured", "Effect [95 % CI] (n); MDE", "Effect [95\\% CI] (n); MDE"),
            Column("mark", "Control", "Control")]
    cap = ("Positive controls: settings where each mechanism must show if it is implemented right (control grids, "
           "docs/grids.md). Effect = row minus the control's reference row. marked = the interval excludes zero on "
           "the expected side; a control with no marked row makes the claims it guards 'blind' in the paper-claims "
           "table.")
    return [Table("claims_controls", "Positive controls", cap, ["Control", "Study (metric)", "Scene", "Row"], cols,
                  rows, section="claims")]
