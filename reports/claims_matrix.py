"""The claims page's opening: one verdict per claim and regime (the claim x regime matrix), the positive
controls by regime, and the claims no regime of this world can test, with the reason.

Why: a verdict belongs to the regime it was measured in (reports/regimes.py), so the page shows the
claims across the declared regimes (methods/gaussiands/study_table.py, `REGIMES`) before any detail: a
regime with no cells reads "not run", a blind cell reads "blind" with its reason. A declared regime is
a column as soon as it is declared; its cells fill in when its grids are published.
"""
from __future__ import annotations

from gsbench.methods.gaussiands import study_table
from gsbench.methods.gaussiands.study_table import REGIMES, Claim, Regime
from gsbench.reports.claims_spread import setting_table, variance_shares
from gsbench.reports.claims_table import BLIND, NOT_RUN, ClaimRow
from gsbench.reports.controls import MARKED, regime_marks
from gsbench.reports.data import Results
from gsbench.reports.display import metric_spec
from gsbench.reports.regimes import EXACT_DEPTH, declared, differences, guard_note, regime_label, run_regimes
from gsbench.reports.table import Cell, Column, Row, Table

UNTESTABLE_MARK = "†"
# Claims no regime of this world can test, and why (docs/grids.md, "Regimes"): the simulated mask prior
# fixes every semantic label before training, and no loss term changes which class a target says.
FIXED_LABELS = ("the semantic labels are fixed before training (the simulated mask prior draws its failures per "
                "seed, the capture's labels are given), and no loss term changes which class a target says")
UNTESTABLE: dict[str, str] = {
    "loss_ds_miou": "the paper's +37 points imply a baseline far below what L_sem alone reaches",
    "loss_all_miou": "the paper's +50 points imply a baseline far below what L_sem alone reaches",
    "lambda_depth_r": "lambda_depth weights a geometry term",
    "lambda_sem_r": "a larger lambda_sem fits the same labels harder (lambda_sem 5 against 0 is the control, and "
                    "it marks)",
    "depth_ss_raw_mbiou": "the boundaries, too, are the mask prior's",
    "depth_ss_mm_mbiou": "the boundaries, too, are the mask prior's",
}


def _verdict_head(text: str) -> str:
    """A verdict without its ':' detail, blind verdicts with their reason."""
    return text if text.startswith(BLIND) else text.split(":", 1)[0]


def matrix_columns(rows: list[ClaimRow]) -> list[tuple[str, Regime]]:
    """(header, regime): the declared regimes in order, then every other regime a claim row ran in."""
    cols = [(d.name, d.regime) for d in REGIMES]
    for r in rows:
        if r.regime is not None and declared(r.regime) is None and all(r.regime != reg for _h, reg in cols):
            cols.append((f"other: {regime_label(r.regime)}", r.regime))
    return cols


def matrix_table(rows: list[ClaimRow], claims: list[Claim] | None = None) -> Table:
    """One row per claim, one column per regime: the verdict there ('not run' where the claim has no
    cell in the regime); the claims in UNTESTABLE carry the mark listed under the table."""
    claims = study_table.paper_claims() if claims is None else claims
    cols = matrix_columns(rows)
    out = []
    for c in claims:
        cells = []
        for _h, reg in cols:
            got = [_verdict_head(r.measured.verdict) for r in rows
                   if r.claim.key == c.key and r.regime == reg and r.measured is not None]
            cells.append(Cell(text=" / ".join(got) if got else NOT_RUN))
        mark = f" {UNTESTABLE_MARK}" if c.key in UNTESTABLE else ""
        out.append(Row([c.text + mark], cells))
    columns = [Column(f"regime{i}", h, h) for i, (h, _r) in enumerate(cols)]
    cap = ("One verdict per claim and regime (the detailed table 'Paper claims' below gives each cell's interval, "
           "guard and p-values). A cell reads 'blind' when its interval includes zero and no positive control of "
           "the claim is marked in that regime; 'not run' when the claim has no published cell there. "
           f"{UNTESTABLE_MARK}: no regime of this world can test the claim (listed under the table).")
    return Table("claims_matrix", "Claim x regime", cap, ["Claim"], columns, out, section="claims")


def regime_lines(kinds: dict[str, str] | None = None) -> list[str]:
    """One line per declared regime: its name, what it is, and why it is a column."""
    return [f"- **{d.name}** ({d.kind}): {regime_label(d.regime, kinds=kinds, name=False)}; {d.why}."
            for d in REGIMES]


def _seed_share(res: Results, claim: Claim) -> str:
    """' (seed share of mIoU (%) variance in lambda_grid: 100 %)', from the study's complete setting x seed
    table in its first regime; '' when the table is too small."""
    ids = res.run_ids(study=claim.study)
    if not ids:
        return ""
    regimes = run_regimes(res)
    first = regimes[ids[0]]
    ids = [r for r in ids if regimes[r] == first]
    concrete = res.resolve(claim.metric, res.runs.at[ids[0], "protocol"])
    if concrete is None:
        return ""
    sp = metric_spec(claim.metric)
    table, _n = setting_table(res, ids, concrete, sp.scale)
    shares = variance_shares(table)
    if shares is None:
        return ""
    return f"; the seed explains {100 * shares.seed:.0f} % of {claim.study}'s {sp.label} variance"


def untestable_lines(res: Results | None, claims: list[Claim] | None = None) -> list[str]:
    """The claims no regime of this world can test, each with its reason (and, with cells, the seed's share
    of the study's variance)."""
    claims = study_table.paper_claims() if claims is None else claims
    out = []
    for c in claims:
        if c.key in UNTESTABLE:
            share = _seed_share(res, c) if res is not None else ""
            out.append(f"- {UNTESTABLE_MARK} {c.text}: {UNTESTABLE[c.key]}{share}.")
    return out


def _control_cell(res_marks: dict[Regime, str], regime: Regime) -> str:
    """A control's status in one declared regime: its mark where it ran there, or with the exact version
    of the regime's depth prior (named); 'not run' elsewhere."""
    for reg, st in res_marks.items():
        note = guard_note(reg, regime)
        if note is not None:
            return st + (f" ({EXACT_DEPTH})" if note else "")
    return NOT_RUN


def controls_by_regime(res: Results | None) -> Table:
    """One row per control that guards claims: its status in each declared regime, and where else it ran
    (with what separates that regime from the nearest declared one)."""
    out = []
    ran = regime_marks(res) if res is not None else []
    for c in study_table.controls():
        if not c.guards:
            continue
        marks = {reg: st for control, reg, st, _ in ran if control.key == c.key}
        cells = [Cell(text=_control_cell(marks, d.regime)) for d in REGIMES]
        elsewhere = []
        for reg, st in marks.items():
            if any(guard_note(reg, d.regime) is not None for d in REGIMES):
                continue
            near = min(REGIMES, key=lambda d: len(differences(reg, d.regime)))
            elsewhere.append(f"{st} in {regime_label(reg)} (against {near.name}: "
                             f"{'; '.join(differences(reg, near.regime))})")
        cells.append(Cell(text="; ".join(elsewhere) or "–"))
        out.append(Row([c.key, c.text, ", ".join(c.guards)], cells))
    columns = [Column(f"regime{i}", d.name, d.name) for i, d in enumerate(REGIMES)]
    columns.append(Column("elsewhere", "Ran only in another regime", "Ran only in another regime"))
    cap = ("The positive controls that guard claims, by regime: 'marked' / 'unmarked' where the control ran in the "
           f"regime ('{EXACT_DEPTH}' where it used the exact version of the regime's depth prior, the one "
           "difference a guard may have), 'not run' where it did not. A control guards a claim only in a regime "
           f"where it is {MARKED}; the last column names the regimes it ran in instead, and what separates each "
           "from the nearest declared regime.")
    return Table("claims_controls_by_regime", "Positive controls by regime", cap, ["Control", "Setting", "Guards"],
                 columns, out, section="claims")
