"""Positive controls of the paper-claims table: for each mechanism a setting where its effect must
exist if the implementation is right (the control grids, docs/grids.md; each control is declared on its
control study in methods/gaussiands/study_table.py). A control is *marked* when
its best row survives Holm's correction across the control's rows (the rows' p-values from the t
statistics of their intervals, family-wise 5 %) on the expected side. Why Holm: with many rows, some
interval excludes zero by chance (12 rows of no effect: about one in five controls), and a falsely
marked control would un-blind the claims it guards. A claim whose control ran and is not marked, and
whose own interval includes zero, is "blind" in the claims table: the study could not have seen the
mechanism, so its interval says nothing about the paper's effect.

A control guards a claim only in the regime it ran in (reports/regimes.py: the scene, the training views,
the preset and the prior providers; the exact version of the claim's depth prior is allowed and named).
With no marked control in a claim's regime, a claim whose interval includes zero reads "blind: no control
in this regime".
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from gsbench.methods.gaussiands import study_table
from gsbench.methods.gaussiands.study_table import CONTROLS, REGIMES, Control, Regime  # noqa: F401  (CONTROLS: the shipped ones)
from gsbench.reports.data import Results, is_null, same
from gsbench.reports.display import metric_spec
from gsbench.reports.regimes import guard_note, regime_label, run_regimes
from gsbench.reports.stats import ALPHA, Diff, compare, family_note, holm
from gsbench.reports.studies import PROTOCOL_SHORT, _axis_label, _axis_rank, _get
from gsbench.reports.table import Cell, Column, Row, Table

MARKED, UNMARKED, OPPOSITE, NOT_RUN = "marked", "unmarked", "opposite", "not run"
NO_CONTROL = "blind: no control in this regime"


def scene_label(scene: str, protocol: Any, kinds: dict[str, str] | None = None) -> str:
    """'tabletop-medium-0 (synthetic; 3D-OVS protocol)': the scene, whether gsbench generated it or it
    is a real capture (when `kinds` knows it), and the semantic protocol it is scored with."""
    proto = PROTOCOL_SHORT.get(protocol, protocol)
    kind = (kinds or {}).get(scene)
    return f"{scene} ({kind}; {proto} protocol)" if kind else f"{scene} ({proto})"


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
    regime: Regime | None = None

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


def regime_groups(res: Results, ids: list[str]) -> list[tuple[Regime, Any, list[str]]]:
    """(regime, protocol, runs) of the runs `ids`: the declared regimes first, in their order, then the
    others by scene and label."""
    regimes = run_regimes(res)
    groups: dict[tuple, list[str]] = {}
    for r in ids:
        pr = res.runs.at[r, "protocol"]
        groups.setdefault((regimes[r], None if is_null(pr) else pr), []).append(r)
    order = [d.regime for d in REGIMES]

    def rank(key: tuple) -> tuple:
        reg, pr = key
        return (order.index(reg) if reg in order else len(order), regime_label(reg), str(pr))
    return [(reg, pr, groups[(reg, pr)]) for reg, pr in sorted(groups, key=rank)]


def _measure_rows(res: Results, c: Control, kinds: dict[str, str] | None = None) -> list[ControlRow]:
    """The control's rows, regime by regime, before marking."""
    ids = [r for r in res.run_ids(study=c.study)
           if all(any(same(_get(res, r, a), v) for v in values) for a, values in c.where.items())]
    sp = metric_spec(c.metric)
    out = []
    for regime, pr, sids in regime_groups(res, ids):
        concrete = res.resolve(c.metric, pr)
        ref = [r for r in sids if all(same(_get(res, r, k), v) for k, v in c.reference.items())]
        combos: list[tuple] = []
        for r in sids:
            t = tuple(_get(res, r, a) for a in c.axes)
            if r not in ref and not any(all(same(x, y) for x, y in zip(t, u)) for u in combos):
                combos.append(t)
        combos.sort(key=lambda t: tuple(_axis_rank(a, v) for a, v in zip(c.axes, t)))
        scene = regime_label(regime, pr, kinds)
        for t in combos:
            label = ", ".join(f"{a.rsplit('.', 1)[-1]}={_axis_label(a, v)}" for a, v in zip(c.axes, t))
            rows = [r for r in sids if all(same(_get(res, r, a), v) for a, v in zip(c.axes, t))]
            va = res.seed_values(rows, concrete, sp.scale) if concrete else {}
            # the reference at the row's values of the axes the reference leaves free (the same train.views)
            free = [(a, v) for a, v in zip(c.axes, t) if a not in c.reference]
            paired = [r for r in ref if all(same(_get(res, r, a), v) for a, v in free)]
            vb = res.seed_values(paired, concrete, sp.scale) if concrete else {}
            if not va or not vb:
                out.append(ControlRow(scene, label, None, "n/a (" + ("row" if not va else "reference") + " not run)",
                                      regime=regime))
                continue
            out.append(ControlRow(scene, label, compare(va, vb), starved(res, rows, c.inputs) or "", regime=regime))
    return out


def control_rows(res: Results, c: Control, kinds: dict[str, str] | None = None) -> list[ControlRow]:
    """Every (scene, row) of the control with its mark (mark_rows over all of them); one 'not run' row
    when its study has no run."""
    if not res.run_ids(study=c.study):
        return [ControlRow("–", "–", None, "study not run")]
    rows = _measure_rows(res, c, kinds)
    if not rows:
        return [ControlRow("–", "–", None, "no run in the control's setting")]
    for row, (mark, holm_p) in zip(rows, mark_rows([r.diff for r in rows], c.direction)):
        row.mark, row.holm_p = mark, holm_p
    return rows


def control_status(res: Results, c: Control) -> str:
    """marked when its best row survives Holm on the expected side; not run when no row has a
    measurement; else unmarked / opposite."""
    return status_of([r.mark for r in control_rows(res, c)])


def status_of(marks: list[str]) -> str:
    """A control's status from its rows' marks (all its rows, or those of one regime)."""
    if MARKED in marks:
        return MARKED
    if all(m == NOT_RUN for m in marks):
        return NOT_RUN
    return OPPOSITE if OPPOSITE in marks and UNMARKED not in marks else UNMARKED


def regime_marks(res: Results) -> list[tuple[Control, Regime, str, str]]:
    """(control, a regime it ran in, its status there, its best marked row there or '') for every control
    that guards a claim; the rows are marked across the whole control (Holm over all its rows), the status
    is that of the regime's rows."""
    out = []
    for c in study_table.controls():
        if not c.guards or not res.run_ids(study=c.study):
            continue
        by: dict[Regime, list[ControlRow]] = {}
        for r in control_rows(res, c):
            if r.regime is not None:
                by.setdefault(r.regime, []).append(r)
        for reg, rows in by.items():
            marked = sorted((r for r in rows if r.mark == MARKED), key=lambda r: r.holm_p or 0.0)
            out.append((c, reg, status_of([r.mark for r in rows]), marked[0].label if marked else ""))
    return out


@dataclass
class Guard:
    """Which control guards a claim in its regime (`text`, the claims table's Guard column) and the
    verdict a claim whose interval includes zero gets when none is marked there (`blind`, else None)."""
    text: str
    blind: str | None


def claim_guard(marks: list[tuple[Control, Regime, str, str]], claim_key: str, regime: Regime) -> Guard:
    """The guard of one claim in one regime (`regime_marks`): a control guards it only when it ran in the
    claim's regime, or in it with the exact version of the claim's depth prior (named); the guard names the
    control and its best marked row."""
    mine = [m for m in marks if claim_key in m[0].guards]
    notes = [(c, st, row, guard_note(reg, regime)) for c, reg, st, row in mine]
    here = [n for n in notes if n[3] is not None]
    marked = [f"{c.key} marked, row {row}" + (f" ({note})" if note else "")
              for c, st, row, note in here if st == MARKED]
    if marked:
        return Guard("; ".join(marked), None)
    ran = [(c, st, note) for c, st, _row, note in here if st in (UNMARKED, OPPOSITE)]
    if ran:
        c, st, note = ran[0]
        return Guard(f"{c.key} {st}" + (f" ({note})" if note else ""), f"blind: control {c.key} {st}")
    keys = sorted({m[0].key for m in mine})
    elsewhere = f"none here ({', '.join(keys)} ran in another regime)" if keys else "none declared for this claim"
    return Guard(elsewhere, NO_CONTROL)


def controls_table(res: Results, kinds: dict[str, str] | None = None) -> list[Table]:
    """One row per control and compared setting: the effect against the control's reference row
    with its 95 % interval, MDE and Holm p-value, and whether it is marked (no table when no control ran)."""
    declared = study_table.controls()
    if not any(res.run_ids(study=c.study) for c in declared):
        return []
    rows, k = [], 0
    for c in declared:
        ref = ", ".join(f"{a.rsplit('.', 1)[-1]}={_axis_label(a, v)}" for a, v in c.reference.items())
        decimals = metric_spec(c.metric).decimals
        for r in control_rows(res, c, kinds):
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
           "Regime = where the control ran (scene, training views, preset, prior providers; docs/grids.md, "
           "\"Regimes\"): a control guards a claim only in the claim's own regime, or in it with the exact "
           "version of the claim's depth prior. A claim whose interval includes zero reads 'blind' where no control "
           "is marked in its regime.")
    return [Table("claims_controls", "Positive controls", cap, ["Control", "Study (metric)", "Regime", "Row"], cols,
                  rows, section="claims")]
