"""Positive controls of the paper-claims table: for each mechanism a setting where its effect must
exist if the implementation is right (the control grids, docs/grids.md). A control is *marked* when
its best row survives Holm's correction across the control's rows (the rows' p-values from the t
statistics of their intervals, family-wise 5 %) on the expected side. Why Holm: with many rows, some
interval excludes zero by chance (12 rows of no effect: about one in five controls), and a falsely
marked control would un-blind the claims it guards. A claim whose control ran and is not marked, and
whose own interval includes zero, is "blind" in the claims table: the study could not have seen the
mechanism, so its interval says nothing about the paper's effect.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from gsbench.methods.gaussiands.paper import DS_INPUTS
from gsbench.reports.data import Results, same

from gsbench.reports.display import (AX_LAMBDAS, AX_LATENT, AX_LOSSES, AX_NOISE_SEVERITY, AX_NOISE_TYPE,  # isort: skip
                                  AX_VIEWS, metric_spec)
from gsbench.reports.stats import ALPHA, Diff, compare, family_note, holm
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
    where: dict = field(default_factory=dict)    # axis -> the values the control's runs are taken from ({} = all)


_DEPTH_CLAIMS = ("depth_ss_raw_psnr", "depth_mm_raw_psnr", "depth_ss_mm_psnr", "depth_ss_raw_mbiou",
                 "depth_ss_mm_mbiou", "loss_depth_psnr", "lambda_depth_r")
CONTROLS: list[Control] = [
    # the guard is the 3-view rows, where the references find the depth term's gain; the 6- and 9-view
    # rows show it shrink (their own Holm family, guarding nothing), so they cannot dilute the guard
    Control("depth_psnr", "3 views: L_depth with an exact prior raises held-out PSNR", "control_depth", "psnr", +1,
            (AX_VIEWS, AX_LAMBDAS[0]), {AX_LAMBDAS[0]: 0.0}, _DEPTH_CLAIMS, where={AX_VIEWS: (3,)}),
    Control("depth_error", "3 views: L_depth with an exact prior lowers the depth error on covered pixels",
            "control_depth", "depth_absrel_covered", -1, (AX_VIEWS, AX_LAMBDAS[0]), {AX_LAMBDAS[0]: 0.0},
            where={AX_VIEWS: (3,)}),
    Control("depth_psnr_more_views", "6 and 9 views: the PSNR gain of L_depth (expected to shrink)", "control_depth",
            "psnr", +1, (AX_VIEWS, AX_LAMBDAS[0]), {AX_LAMBDAS[0]: 0.0}, where={AX_VIEWS: (6, 9)}),
    Control("depth_error_more_views", "6 and 9 views: the covered-pixel depth error under L_depth", "control_depth",
            "depth_absrel_covered", -1, (AX_VIEWS, AX_LAMBDAS[0]), {AX_LAMBDAS[0]: 0.0}, where={AX_VIEWS: (6, 9)}),
    Control("depth_noise", "few views, lambda_depth 1: noise on the depth prior lowers PSNR", "control_depth_noise",
            "psnr", -1, (AX_NOISE_TYPE, AX_NOISE_SEVERITY), {AX_NOISE_TYPE: None, AX_NOISE_SEVERITY: 0},
            ("noise_motion_blur", "noise_gaussian", "noise_poisson", "noise_salt_pepper")),
    # does the noise reach the geometry at all? The same runs, the rendered-depth error; it guards nothing:
    # the depth-noise claims are about PSNR, so only the PSNR control can un-blind them
    Control("depth_noise_error", "few views, lambda_depth 1: noise on the depth prior raises the depth error "
            "on covered pixels", "control_depth_noise", "depth_absrel_covered", +1, (AX_NOISE_TYPE, AX_NOISE_SEVERITY),
            {AX_NOISE_TYPE: None, AX_NOISE_SEVERITY: 0}),
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


@dataclass
class ControlRow:
    """One compared row of a control on one scene: its difference to the reference and its mark."""
    scene: str
    label: str
    diff: Diff | None     # None: the row or the reference has no value
    note: str = ""        # why there is no difference, or the input the row lacked
    mark: str = NOT_RUN
    holm_p: float | None = None  # Holm-adjusted p-value across the control's rows, None = no interval

    def text(self, decimals: int) -> str:
        """The row's effect with its interval, MDE, Holm p-value and note."""
        if self.diff is None:
            return self.note
        d = self.diff
        mde = f"; MDE {d.mde:.{decimals}f}" if d.mde is not None else ""
        holm_p = f"; Holm p {self.holm_p:.3g}" if self.holm_p is not None else ""
        return d.text(decimals) + mde + holm_p + (f"; {self.note}" if self.note else "")


def mark_rows(diffs: list[Diff | None], direction: int) -> list[tuple[str, float | None]]:
    """(mark, Holm-adjusted p) of each row of one control. The rows with an interval form the family:
    their p-values (from the t statistics of their intervals) are Holm-corrected together, so that a
    control with no true effect is marked at most 5 % of the time however many rows it has. A row is
    marked when it survives the correction on the expected side, opposite when it survives on the other."""
    tested = [i for i, d in enumerate(diffs) if d is not None and d.p is not None]
    adjusted = dict(zip(tested, holm([diffs[i].p for i in tested])))  # type: ignore[union-attr,misc]
    out: list[tuple[str, float | None]] = []
    for i, d in enumerate(diffs):
        if d is None:
            out.append((NOT_RUN, None))
        elif i not in adjusted:
            out.append((UNMARKED, None))
        elif adjusted[i] > ALPHA:
            out.append((UNMARKED, adjusted[i]))
        else:
            expected = (d.delta > 0.0) == (direction > 0)  # type: ignore[operator]
            out.append((MARKED if expected else OPPOSITE, adjusted[i]))
    return out


def _measure_rows(res: Results, c: Control) -> list[ControlRow]:
    """The control's rows, scene by scene, before marking."""
    ids = [r for r in res.run_ids(study=c.study)
           if all(any(same(_get(res, r, a), v) for v in values) for a, values in c.where.items())]
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
        for t in combos:
            label = ", ".join(f"{a.rsplit('.', 1)[-1]}={_axis_label(a, v)}" for a, v in zip(c.axes, t))
            rows = [r for r in sids if all(same(_get(res, r, a), v) for a, v in zip(c.axes, t))]
            va = res.seed_values(rows, concrete, sp.scale) if concrete else {}
            # the reference at the row's values of the axes the reference leaves free (the same train.views)
            free = [(a, v) for a, v in zip(c.axes, t) if a not in c.reference]
            paired = [r for r in ref if all(same(_get(res, r, a), v) for a, v in free)]
            vb = res.seed_values(paired, concrete, sp.scale) if concrete else {}
            if not va or not vb:
                out.append(ControlRow(scene, label, None, "n/a (" + ("row" if not va else "reference") + " not run)"))
                continue
            out.append(ControlRow(scene, label, compare(va, vb), starved(res, rows, c.inputs) or ""))
    return out


def control_rows(res: Results, c: Control) -> list[ControlRow]:
    """Every (scene, row) of the control with its mark (mark_rows over all of them); one 'not run' row
    when its study has no run."""
    if not res.run_ids(study=c.study):
        return [ControlRow("–", "–", None, "study not run")]
    rows = _measure_rows(res, c)
    if not rows:
        return [ControlRow("–", "–", None, "no run in the control's setting")]
    for row, (mark, holm_p) in zip(rows, mark_rows([r.diff for r in rows], c.direction)):
        row.mark, row.holm_p = mark, holm_p
    return rows


def control_status(res: Results, c: Control) -> str:
    """marked when its best row survives Holm on the expected side; not run when no row has a
    measurement; else unmarked / opposite."""
    marks = [r.mark for r in control_rows(res, c)]
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
    with its 95 % interval, MDE and Holm p-value, and whether it is marked (no table when no control ran)."""
    if not any(res.run_ids(study=c.study) for c in CONTROLS):
        return []
    rows, k = [], 0
    for c in CONTROLS:
        ref = ", ".join(f"{a.rsplit('.', 1)[-1]}={_axis_label(a, v)}" for a, v in c.reference.items())
        decimals = metric_spec(c.metric).decimals
        for r in control_rows(res, c):
            k += r.diff is not None and r.diff.has_interval
            rows.append(Row([c.text, f"{c.study} ({metric_spec(c.metric).label})", r.scene, f"{r.label} vs {ref}"],
                            [Cell(text=r.text(decimals)), Cell(text=r.mark)]))
    cols = [Column("measured", "Effect [95 % CI] (n); MDE; Holm p", "Effect [95\\% CI] (n); MDE; Holm p"),
            Column("mark", "Control", "Control")]
    cap = ("Positive controls: settings where each mechanism must show if it is implemented right (control grids, "
           "docs/grids.md). Effect = row minus the control's reference row, paired on the seeds both ran. "
           "* = the row's own interval excludes zero. " + family_note(k) + " So a row is marked only when its "
           "p-value (from the t statistic of its interval) survives Holm's correction across its control's rows "
           "(Holm p at most 0.05) on the expected side, and a control is marked when its best row "
           "is: a control with no true effect is then marked at most 5 % of the time, however many rows it has. "
           "A control that ran with no marked row makes the claims it guards 'blind' in the paper-claims table "
           "where their own interval includes zero.")
    return [Table("claims_controls", "Positive controls", cap, ["Control", "Study (metric)", "Scene", "Row"], cols,
                  rows, section="claims")]
