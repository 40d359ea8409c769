"""The claims page across backends: the same claims plan published by more than one renderer (e.g.
results/cpu by the CPU rasterizer and results/gpu by gsplat on a lent GPU), one verdict column per
store, and whether the verdicts agree.

Why: a verdict is about the method, so it must not depend on which renderer trained the cells. The
numbers of two backends differ in their last bits (and, after 800 chaotic steps, by about a seed's
spread), so the page compares verdicts, not numbers: each store's rows are measured, guarded and
Holm-corrected on their own, exactly as the page's main tables, and matched by claim and regime (a
regime does not include the backend: reports/regimes.py).
"""
from __future__ import annotations

from dataclasses import dataclass

from gsbench.reports.claims_table import BLIND, NOT_RUN, ClaimRow
from gsbench.reports.regimes import regime_label
from gsbench.reports.table import Cell, Column, Row, Table

AGREE = "agree"
DIFFER = "differ"
MISSING = "not run on every backend"


@dataclass
class StoreRows:
    """One store's claim rows: `label` names the store and its backend in the table's header."""
    label: str
    rows: list[ClaimRow]


def verdict_class(text: str) -> str:
    """The verdict's word without its qualifiers or detail: 'opposite (fails Holm)' -> 'opposite',
    'blind: control ... unmarked' -> 'blind', 'not reproduced: at most +0.76' -> 'not reproduced'."""
    head = text.split(":", 1)[0]
    return head.split(" (", 1)[0].strip()


def _verdicts(rows: list[ClaimRow]) -> dict[tuple, str]:
    """(claim key, regime) -> the row's verdict as printed (a row that did not run is left out)."""
    return {(r.claim.key, r.regime): r.measured.verdict for r in rows
            if r.regime is not None and r.measured is not None}


def agreement(verdicts: list[str | None]) -> str:
    """'agree' when every store has the row with the same verdict word; 'differ' when two that have it
    disagree; else 'not run on every backend'. Blind verdicts agree when both are blind, whatever the
    reason each gives."""
    classes = [verdict_class(v) for v in verdicts if v is not None]
    if len(set(classes)) > 1:
        return DIFFER
    if len(classes) < len(verdicts) or not classes:
        return MISSING
    return AGREE


def backends_table(stores: list[StoreRows]) -> Table:
    """One row per claim and regime any store ran: the verdict in each store ('not run' where it has no
    cell) and whether they agree."""
    found = [_verdicts(s.rows) for s in stores]
    labels: dict[tuple, list[str]] = {}         # (claim key, regime) -> [claim text, regime label], first seen
    for s in stores:
        for r in s.rows:
            if r.regime is not None:
                labels.setdefault((r.claim.key, r.regime), [r.claim.text, regime_label(r.regime)])
    out = []
    for key, row_labels in labels.items():
        got = [f.get(key) for f in found]
        cells = [Cell(text=v if v is not None else NOT_RUN) for v in got] + [Cell(text=agreement(got))]
        out.append(Row(row_labels, cells))
    columns = [Column("verdict", s.label, s.label) for s in stores] + [Column("backends", "Across backends",
                                                                              "Across backends")]
    caption = ("Each store's verdicts, measured, guarded and Holm-corrected on its own cells; matched by claim and "
               f"regime. {AGREE}: the same verdict word in every store ({BLIND} counts as one word, whatever its "
               f"reason); {DIFFER}: two stores disagree; {MISSING}: a store has no cell of the row.")
    return Table("claims_backends", "Claims across backends", caption, ["Claim", "Regime"], columns, out,
                 section="claims")


def agreement_summary(table: Table) -> str:
    """'agree 30, differ 2, not run on every backend 60' over the table's rows."""
    counts: dict[str, int] = {}
    for row in table.rows:
        word = row.cells[-1].text
        counts[word] = counts.get(word, 0) + 1
    return ", ".join(f"{w} {counts[w]}" for w in (AGREE, DIFFER, MISSING) if w in counts) or "no row"


def backends_section(stores: list[StoreRows]) -> tuple[list[str], str]:
    """The page's 'Across backends' section and the README block's sentence on it (nothing with one store)."""
    if len(stores) < 2:
        return [], ""
    table = backends_table(stores)
    names, summary = ", ".join(s.label for s in stores), agreement_summary(table)
    return (["## Across backends", "", f"The same plan published by {len(stores)} stores: {names}. Verdicts by claim "
             f"and regime: {summary}.", "", table.to_markdown()], f" Across backends ({names}): {summary}.")
