"""The "paper claims" table: each claim of the paper's ablation section, the paper's number, gsbench's
measured effect with its 95 % interval, the minimum detectable effect (MDE) at its n, and a verdict
that follows only from that interval.

Why a data table: the paper's numbers live beside the method (methods/gaussiands/paper.py,
PAPER_CLAIMS, each with the section and table or figure it comes from), and the verdict rules are
the same for every row. Interval and
paper number are in the same display units (PSNR in dB, IoU in %, r as is):
- claim with a number P (sized against the paper; "above"/"below" read on the paper's side of zero):
  reproduced when the interval excludes zero on P's side and reaches P; smaller than claimed when it
  excludes zero on P's side but lies wholly short of P; not reproduced when it contains zero and lies
  wholly short of P (the row prints the largest effect still compatible); opposite when it excludes
  zero on the other side; inconclusive when it contains both zero and P (or has no interval);
- directional claim without a number: reproduced / opposite when the interval excludes zero on the
  paper's / the other side, inconclusive when it includes zero or has no interval (one seed);
- robustness claim (the paper says "no real change"): reproduced when the interval lies inside
  +-margin, opposite when it lies wholly beyond the margin on the harmful side, else inconclusive.
  The margin is gsbench's own, fixed here before any run, not a number of the paper;
- not run: the study, or one of the two rows it compares, has no finished run with the metric;
- not testable: the resolver dropped the setting the claim is about (e.g. no depth prior);
- blind: any verdict whose interval includes zero (or that has none) while the claim's positive control
  ran and is not marked, or while the compared row lacked what the mechanism acts on (`Claim.inputs`,
  e.g. an empty L_ds edge map). A robustness "reproduced" is included: a study that cannot see the
  mechanism also shows "no change". An interval that excludes zero is never blinded.
The paper's number is compared and printed at the paper's decimals (`Claim.paper_decimals`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from gsbench.methods.gaussiands.paper import MAX, PAPER_CLAIMS, ROBUST_MARGIN_DB, Claim
from gsbench.reports.ablations import _covered, run_dropped
from gsbench.reports.controls import blind_claims, starved
from gsbench.reports.data import Results, same
from gsbench.reports.display import metric_spec
from gsbench.reports.stats import (
    SEEDS_CAP,
    Diff,
    compare,
    family_note,
    mde_r,
    pearson,
    pearson_interval,
    runs_for_r,
    seeds_for_mde,
)
from gsbench.reports.studies import PROTOCOL_SHORT, _get, scene_protocols
from gsbench.reports.sweeps import lambda_points
from gsbench.reports.table import Cell, Column, Row, Table
from gsbench.train.losses import EDGE_FLOOR

REPRODUCED, OPPOSITE, INCONCLUSIVE, NOT_RUN, NOT_TESTABLE = (
    "reproduced", "opposite", "inconclusive", "not run", "not testable")
SMALLER, NOT_REPRODUCED, BLIND = "smaller than claimed", "not reproduced", "blind"
CLAIM_COLUMNS = [Column("paper", "Paper", "Paper"),
                 Column("measured", "gsbench [95 % CI] (n)", "gsbench [95\\% CI] (n)"),
                 Column("mde", "MDE", "MDE"), Column("verdict", "Verdict", "Verdict"),
                 Column("seeds", "Seeds for the MDE", "Seeds for the MDE")]


def paper_text(claim: Claim) -> str:
    """The paper's number at its decimals, with its note."""
    return ((f"{claim.paper:+.{claim.paper_decimals}f}" if claim.paper is not None else "–")
            + (f" ({claim.paper_note})" if claim.paper_note else ""))


def not_run_row(claim: Claim) -> Row:
    """The row of a claim whose study has no run."""
    cells = [paper_text(claim), "study not run", "–", NOT_RUN, "–"]
    return Row([claim.text, claim.source, "–"], [Cell(text=t) for t in cells])


def verdict(direction: int, lo: float | None, hi: float | None, paper: float | None = None,
            margin: float = ROBUST_MARGIN_DB, decimals: int | None = None) -> str:
    """The verdict of one claim from the interval [lo, hi] of (row - reference), or of r; with the
    paper's number `paper` the verdict is sized against it (module docstring), at the paper's precision
    when `decimals` (the paper's) is given: an interval that reaches +2.62 at two decimals reaches +2.62."""
    if lo is None or hi is None:
        return INCONCLUSIVE
    if direction == 0:  # robustness: harmful side is negative (a drop)
        if -margin <= lo and hi <= margin:
            return REPRODUCED
        if hi < -margin:
            return OPPOSITE
        return INCONCLUSIVE
    if paper is not None and (paper > 0.0) != (direction > 0):
        raise ValueError(f"claim direction {direction:+d} disagrees with the sign of the paper's number {paper}")
    # on the paper's side: a = the near end, b = the far end of the interval, p = |paper|
    a, b = (lo, hi) if direction > 0 else (-hi, -lo)
    if b < 0.0:
        return OPPOSITE
    if paper is None:
        return REPRODUCED if a > 0.0 else INCONCLUSIVE
    far = b if decimals is None else round(b, decimals)
    short = far < abs(paper)  # the whole interval lies short of the paper's value
    if a > 0.0:
        return SMALLER if short else REPRODUCED
    return NOT_REPRODUCED if short else INCONCLUSIVE


def verdict_text(v: str, direction: int, lo: float | None, hi: float | None, paper: float | None,
                 decimals: int) -> str:
    """The verdict with, when the interval lies short of the paper's number, the largest effect on the
    paper's side it still allows ("at most +0.14, paper +37.30"), both at `decimals`, the paper's."""
    if v not in (SMALLER, NOT_REPRODUCED) or lo is None or hi is None or paper is None:
        return v
    bound = f"at most {hi:+.{decimals}f}" if direction > 0 else f"at least {lo:+.{decimals}f}"
    return f"{v}: {bound}, paper {paper:+.{decimals}f}"


def _select(res: Results, ids: list[str], sel: dict) -> list[str]:
    """Runs among ids whose columns match the selector; MAX picks the highest value present among the
    runs that match the rest of the selector."""
    fixed = {k: v for k, v in sel.items() if v != MAX}
    out = [r for r in ids if all(same(_get(res, r, k), v) for k, v in fixed.items())]
    for k, v in sel.items():
        if v == MAX:
            vals = [float(_get(res, r, k)) for r in out if _get(res, r, k) is not None]
            if not vals:
                return []
            out = [r for r in out if _get(res, r, k) is not None and same(float(_get(res, r, k)), max(vals))]
    return out


def _dropped_reason(res: Results, rids: list[str], axes: list[str]) -> str | None:
    for r in rids:
        d = run_dropped(res, r)
        for a in axes:
            why = _covered(a, d) if a.startswith("axis.") else None
            if why:
                return why
    return None


@dataclass
class Measured:
    """One row's measurement: the effect text, the verdict (with its bound), the MDE text, and whether
    the verdict rests on an interval that includes zero (or on none), the only verdicts a blind
    control may replace."""
    text: str
    verdict: str
    mde: str = "–"
    no_effect: bool = False
    interval: bool = False  # the text prints a 95 % interval (counted in the caption's family)
    seeds: str = "–"        # the seed rule: seeds (runs for r) the MDE needs to reach its target


def _mde_text(mde: float | None, decimals: int, why: str) -> str:
    return f"{mde:.{decimals}f}" if mde is not None else f"n/a ({why})"


def seed_target(claim: Claim) -> float | None:
    """The MDE the seed rule asks of a claim, in display units: half the paper's effect (or of its r);
    for a robustness claim, the margin (a drop of that size must be seen); None without either."""
    if claim.direction == 0:
        return ROBUST_MARGIN_DB
    return abs(claim.paper) / 2.0 if claim.paper else None


def _seeds_text(claim: Claim, d: Diff) -> str:
    """'12 (9 more)' / '3 (met)': the paired seeds at which this row's observed spread gives an MDE of at
    most `seed_target`, against the seeds it ran."""
    target = seed_target(claim)
    if target is None:
        return "– (no target)"
    if d.method != "paired" or d.se is None:
        return "n/a (" + ("one seed" if d.method == "paired" else "unpaired") + ")"
    m = seeds_for_mde(d.se, d.n_a, target)
    if m is None:
        return f"> {SEEDS_CAP}"
    return f"{m} (met)" if d.n_a >= m else f"{m} ({m - d.n_a} more)"


def _runs_text(claim: Claim, n: int) -> str:
    """The seed rule for a correlation: runs at which the smallest detectable |r| is half the paper's r."""
    target = seed_target(claim)
    if target is None or target >= 1.0:
        return "– (no target)"
    m = runs_for_r(target)
    return f"{m} runs (met)" if n >= m else f"{m} runs ({m - n} more)"


def measure(res: Results, claim: Claim, scene: str, protocol: Any) -> Measured:
    """Measured effect, verdict and MDE of one claim on one scene."""
    sp = metric_spec(claim.metric)
    concrete = res.resolve(claim.metric, protocol)
    if concrete is None:
        return Measured("n/a (metric not defined for this protocol)", NOT_RUN)
    if claim.correlation:
        xs, ys = lambda_points(res, scene, protocol, claim.correlation, claim.metric)
        mde = _mde_text(mde_r(len(xs)), 2, f"{len(xs)} runs, need 4")
        r, why = pearson(xs, ys)
        if r is None:
            return Measured(f"n/a ({why})", NOT_RUN if len(xs) < 3 else INCONCLUSIVE, mde, len(xs) >= 3)
        ci, runs = pearson_interval(r, len(xs)), _runs_text(claim, len(xs))
        if ci is None:
            return Measured(f"r = {r:+.2f} [n/a: {len(xs)} runs, need 4] (n={len(xs)})", INCONCLUSIVE, mde, True,
                            seeds=runs)
        v = verdict(claim.direction, *ci, paper=claim.paper, decimals=claim.paper_decimals)
        excludes_zero = ci[0] > 0 or ci[1] < 0
        return Measured(f"r = {r:+.2f} [{ci[0]:+.2f}, {ci[1]:+.2f}]{' *' if excludes_zero else ''} (n={len(xs)})",
                        verdict_text(v, claim.direction, *ci, claim.paper, claim.paper_decimals), mde,
                        not excludes_zero, True, runs)
    ids = res.run_ids(study=claim.study, scene=scene, protocol=protocol)
    a, b = _select(res, ids, claim.row), _select(res, ids, claim.reference)
    va, vb = res.seed_values(a, concrete, sp.scale), res.seed_values(b, concrete, sp.scale)
    if not va or not vb:
        return Measured("n/a (" + ("compared row" if not va else "reference row") + " not run or not evaluated)",
                        NOT_RUN)
    why = _dropped_reason(res, a + b, list(claim.row) + list(claim.reference))
    d: Diff = compare(va, vb)
    text = d.text(sp.decimals)
    mde, seeds = _mde_text(d.mde, sp.decimals, d.reason or "no spread"), _seeds_text(claim, d)
    if why:
        return Measured(text + f"; setting dropped: {why}", NOT_TESTABLE, mde, interval=d.has_interval, seeds=seeds)
    v = verdict(claim.direction, d.lo, d.hi, paper=claim.paper, decimals=claim.paper_decimals)
    why_blind = starved(res, a, claim.inputs)
    if why_blind and not d.significant:   # as for controls: an interval that excludes zero is never hidden
        return Measured(text, f"{BLIND}: {why_blind}", mde, True, d.has_interval, seeds)
    return Measured(text, verdict_text(v, claim.direction, d.lo, d.hi, claim.paper, claim.paper_decimals), mde,
                    not d.significant, d.has_interval, seeds)


def claims_table(res: Results, claims: list[Claim] | None = None) -> list[Table]:
    """One row per claim and scene the claim's study ran on ('not run' when it did not run at all);
    no table when none of the claims' studies ran."""
    claims = PAPER_CLAIMS if claims is None else claims
    if not any(res.run_ids(study=c.study) for c in claims):
        return []
    blind = blind_claims(res)
    rows, k = [], 0
    for c in claims:
        ids = res.run_ids(study=c.study)
        pairs = scene_protocols(res, ids) if ids else []
        if not pairs:
            rows.append(not_run_row(c))
            continue
        paper = paper_text(c)
        for sc, pr in pairs:
            m = measure(res, c, sc, pr)
            k += m.interval
            # blind replaces only the verdicts whose interval includes zero (a robustness "reproduced" too,
            # since a blind study also shows no change): an interval that excludes zero shows the mechanism
            # whatever the control says
            if c.key in blind and m.no_effect:
                m.verdict = blind[c.key]
            rows.append(Row([c.text, c.source, f"{sc} ({PROTOCOL_SHORT.get(pr, pr)})"],
                            [Cell(text=paper), Cell(text=m.text), Cell(text=m.mde), Cell(text=m.verdict),
                             Cell(text=m.seeds)]))
    cap = ("Claims of the paper's ablation section against gsbench's measurements: effect = compared row minus "
           "reference row (display units; PSNR in dB, IoU in %), or Pearson r for the lambda claims, with its 95 % "
           "interval (t interval paired on the seeds both rows ran, a dropped seed is named; Welch when they share "
           "none; Fisher z for r). MDE = the smallest true effect this design detects (two-sided 5 % t test, 80 % "
           "power, exact noncentral t) from the observed spread at its n. Paper numbers are compared at the paper's "
           "decimals. Verdict, for a claim "
           "with a number: reproduced (interval excludes zero on the paper's side and reaches the paper's value), "
           "smaller than claimed (excludes zero, lies short of the paper's value), not reproduced (contains zero, "
           "lies short of the paper's value; the largest compatible effect is printed), opposite (excludes zero on "
           "the other side), inconclusive (contains zero and the paper's value, or one seed); without a number "
           "only the side of zero counts; blind = any verdict whose interval includes zero (robustness 'reproduced' "
           "too) while the claim's positive control ran and showed no marked effect (table claims_controls), or "
           "while the compared row lacked what the "
           f"mechanism acts on (for L_ds: an edge map E_d marking under {100 * EDGE_FLOOR:g} % of the pixels); "
           "robustness claims use a "
           f"+-{ROBUST_MARGIN_DB} dB margin chosen by gsbench; not run = no runs. " + family_note(k)
           + " One interval that excludes zero is weak evidence on its own. Seeds for the MDE = the seed rule: how "
           "many paired seeds this row's observed spread needs for an MDE of at most half the paper's effect (for a "
           "robustness claim, at most the margin; for r, the runs at which the smallest detectable |r| is half the "
           "paper's), 'met' when it ran that many.")
    return [Table("paper_claims", "Paper claims", cap, ["Claim", "Paper source", "Scene"], CLAIM_COLUMNS, rows,
                  section="claims")]
