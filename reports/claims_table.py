"""The "paper claims" table: each claim of the paper's ablation section, the paper's number, gsbench's
measured effect with its 95 % interval, what the design could detect at its n, the verdict that
follows from the interval, and the p-value its verdict rests on with its Holm-adjusted value.

Why a data table: the paper's numbers live beside the method (methods/gaussiands/study_table.py,
each claim declared on its study with the section and table or figure it comes from), and the verdict
rules are the same for every row. Interval and
paper number are in the same display units (PSNR in dB, IoU in %, r as is):
- claim with a number P (sized against the paper; "above"/"below" read on the paper's side of zero):
  reproduced when the interval excludes zero on P's side and contains P; larger than claimed when it
  excludes zero and lies wholly beyond P; smaller than claimed when it excludes zero but lies wholly
  short of P; not reproduced when it contains zero and lies wholly short of P (the row prints the
  largest effect still compatible); opposite when it excludes zero on the other side; inconclusive when
  it contains both zero and P (or has no interval);
- directional claim without a number: reproduced / opposite when the interval excludes zero on the
  paper's / the other side, inconclusive when it includes zero or has no interval (one seed);
- robustness claim (the paper says "no real change"): an equivalence test, TOST at 5 % a side against
  +-margin (reports/claims_tests.py): reproduced when both one-sided tests reject (the 90 % interval lies
  inside +-margin), opposite when the 90 % interval lies wholly beyond -margin (the harmful side), else
  inconclusive. The margin is gsbench's own, fixed here before any run, not a number of the paper;
- lambda claim (a Pearson r in the paper): the within-seed r of the seed fixed-effects fit, sized like a
  number P, beside the fit's slope (reports/claims_tests.py);
- not run: the study, or one of the two rows it compares, has no finished run with the metric;
- not testable: the resolver dropped the setting the claim is about (e.g. no depth prior);
- blind: any verdict whose interval includes zero (or that has none) while no positive control of the
  claim is marked in the claim's regime (reports/regimes.py: scene, training views, preset, prior
  providers; a control with the exact version of the claim's depth prior counts, and is named): "blind:
  control K unmarked" when one ran there, "blind: no control in this regime" when none did, or none is
  declared for the claim; or while the compared row lacked what the mechanism acts on (`Claim.inputs`,
  e.g. an empty L_ds edge map). A robustness "reproduced" is included: a study that cannot see the
  mechanism also shows "no change". An interval that excludes zero is never blinded.
Each row is one claim in one regime, and names the control that guards it there.
Every row with an interval enters one Holm family (`holm_qualify`): its p-value is that of the
hypothesis its verdict rejects (zero for reproduced / opposite / inconclusive; the paper's value for not
reproduced; both, the larger p, for larger / smaller than claimed; the margin for robustness). A verdict
that rejects something and fails Holm reads "(fails Holm)"; one from a study whose grid got seeds after
a look at its results reads "(after a second look)".
The paper's number is compared and printed at the paper's decimals (`Claim.paper_decimals`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from gsbench.methods.gaussiands import study_table
from gsbench.methods.gaussiands.study_table import (  # noqa: F401  (PAPER_CLAIMS: the shipped ones)
    MAX,
    PAPER_CLAIMS,
    ROBUST_MARGIN_DB,
    Claim,
    Regime,
)
from gsbench.reports.ablations import _covered, run_dropped
from gsbench.reports.claims_caption import claims_caption
from gsbench.reports.claims_tests import (
    TOST_ALPHA,
    mde_within_r,
    p_r_against,
    seeds_for_tost,
    seeds_for_within_r,
    tost,
    tost_power,
    within_seed,
)
from gsbench.reports.controls import Guard, claim_guard, regime_groups, regime_marks, starved
from gsbench.reports.data import Results, is_null, same
from gsbench.reports.display import metric_spec
from gsbench.reports.regimes import declared, regime_label
from gsbench.reports.stats import ALPHA, SEEDS_CAP, Diff, compare, holm, p_two_sided, seeds_for_mde
from gsbench.reports.studies import _get
from gsbench.reports.table import Cell, Column, Row, Table

REPRODUCED, OPPOSITE, INCONCLUSIVE, NOT_RUN, NOT_TESTABLE = (
    "reproduced", "opposite", "inconclusive", "not run", "not testable")
SMALLER, LARGER, NOT_REPRODUCED, BLIND = "smaller than claimed", "larger than claimed", "not reproduced", "blind"
NOT_MEASURED = "not measured"   # the runs finished but recorded no value for the metric (with their reason)
FAILS_HOLM, SECOND_LOOK = "fails Holm", "after a second look"
# the verdicts that reject a hypothesis (zero, the paper's value or the margin): the ones Holm and a
# second look can qualify
REJECTING = (REPRODUCED, OPPOSITE, LARGER, SMALLER, NOT_REPRODUCED)
CLAIM_COLUMNS = [Column("paper", "Paper", "Paper"),
                 Column("measured", "gsbench [95 % CI] (n)", "gsbench [95\\% CI] (n)"),
                 Column("mde", "MDE", "MDE"), Column("verdict", "Verdict", "Verdict"),
                 Column("seeds", "Seeds for the MDE", "Seeds for the MDE"),
                 Column("p", "p (Holm p)", "p (Holm p)")]


def paper_text(claim: Claim) -> str:
    """The paper's number at its decimals, with its note."""
    return ((f"{claim.paper:+.{claim.paper_decimals}f}" if claim.paper is not None else "–")
            + (f" ({claim.paper_note})" if claim.paper_note else ""))


def not_run_row(claim: Claim) -> Row:
    """The row of a claim whose study has no run."""
    cells = [paper_text(claim), "study not run", "–", NOT_RUN, "–", "–"]
    return Row([claim.text, claim.source, "–", "–"], [Cell(text=t) for t in cells])


def verdict(direction: int, lo: float | None, hi: float | None, paper: float | None = None,
            margin: float = ROBUST_MARGIN_DB, decimals: int | None = None) -> str:
    """The verdict of one claim from the interval [lo, hi] of (row - reference), or of r; with the
    paper's number `paper` the verdict is sized against it (module docstring), at the paper's precision
    when `decimals` (the paper's) is given: an interval that reaches +2.62 at two decimals reaches +2.62.
    For a robustness claim (direction 0) [lo, hi] is the equivalence test's 90 % interval."""
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
    near, far = (a, b) if decimals is None else (round(a, decimals), round(b, decimals))
    short = far < abs(paper)  # the whole interval lies short of the paper's value
    if a > 0.0:
        if short:
            return SMALLER
        return LARGER if near > abs(paper) else REPRODUCED
    return NOT_REPRODUCED if short else INCONCLUSIVE


def verdict_text(v: str, direction: int, lo: float | None, hi: float | None, paper: float | None,
                 decimals: int) -> str:
    """The verdict with, when the interval lies short of (beyond) the paper's number, the largest
    (smallest) effect on the paper's side it still allows ("at most +0.14, paper +37.30"), both at
    `decimals`, the paper's."""
    if v not in (SMALLER, NOT_REPRODUCED, LARGER) or lo is None or hi is None or paper is None:
        return v
    if v == LARGER:
        bound = f"at least {lo:+.{decimals}f}" if direction > 0 else f"at most {hi:+.{decimals}f}"
    else:
        bound = f"at most {hi:+.{decimals}f}" if direction > 0 else f"at least {lo:+.{decimals}f}"
    return f"{v}: {bound}, paper {paper:+.{decimals}f}"


def qualified(text: str, notes: list[str]) -> str:
    """'opposite' + ['fails Holm'] -> 'opposite (fails Holm)'; the qualification goes before the ':'
    detail ('not reproduced (after a second look): at most ...')."""
    if not notes:
        return text
    head, sep, rest = text.partition(":")
    return f"{head} ({'; '.join(notes)}){sep}{rest}"


def rests_on(v: str, direction: int) -> tuple[str, ...]:
    """The hypotheses a verdict rejects (module docstring): 'zero' (no effect), 'paper' (the paper's
    value), 'tost' (a difference of at least the margin), 'harm' (no drop beyond the margin)."""
    if direction == 0:
        return {REPRODUCED: ("tost",), OPPOSITE: ("harm",)}.get(v, ())
    return {REPRODUCED: ("zero",), OPPOSITE: ("zero",), LARGER: ("zero", "paper"), SMALLER: ("zero", "paper"),
            NOT_REPRODUCED: ("paper",)}.get(v, ())


def _tests(**p: float | None) -> dict[str, float]:
    return {k: v for k, v in p.items() if v is not None and math.isfinite(v)}


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
    """One row's measurement: the effect text, the verdict (with its bound), the MDE text, whether
    the verdict rests on an interval that includes zero (or on none), the only verdicts a blind
    control may replace, and the row's tests for the Holm family (hypothesis -> p: every hypothesis
    the verdict rules can reject on this row) with the ones its verdict rests on."""
    text: str
    verdict: str
    mde: str = "–"
    no_effect: bool = False
    interval: bool = False  # the text prints a 95 % interval (counted in the caption's family)
    seeds: str = "–"        # the seed rule: seeds (runs for r) the MDE needs to reach its target
    tests: dict[str, float] = field(default_factory=dict)
    rests: tuple[str, ...] = ()
    p: float | None = None        # the verdict's p (the largest of those it rests on), after Holm
    holm_p: float | None = None   # its Holm-adjusted p (the largest adjusted p it rests on)


def _mde_text(mde: float | None, decimals: int, why: str) -> str:
    return f"{mde:.{decimals}f}" if mde is not None else f"n/a ({why})"


def margin_of(claim: Claim) -> float:
    """A robustness claim's equivalence margin, in the units it is tested in (log units for a ratio)."""
    return ROBUST_MARGIN_DB if claim.margin is None else claim.margin


def margin_text(claim: Claim) -> str:
    """'+-0.5 dB', or for a ratio claim the ratio band '0.80 to 1.25'."""
    m = margin_of(claim)
    if claim.log_ratio:
        return f"{math.exp(-m):.2f} to {math.exp(m):.2f}"
    return f"+-{m:g} {metric_spec(claim.metric).label.split('(')[-1].rstrip(')')}".rstrip()


def seed_target(claim: Claim) -> float | None:
    """The MDE the seed rule asks of a claim, in display units: half the paper's effect (or of its r);
    for a robustness claim, the margin (a drop of that size must be seen); None without either."""
    if claim.direction == 0:
        return margin_of(claim)
    return abs(claim.paper) / 2.0 if claim.paper else None


def _met(m: int | None, have: int, unit: str = "") -> str:
    if m is None:
        return f"> {SEEDS_CAP}{unit}"
    return f"{m}{unit} (met)" if have >= m else f"{m}{unit} ({m - have} more)"


def _seeds_text(claim: Claim, d: Diff) -> str:
    """'12 (9 more)' / '3 (met)': the paired seeds at which this row's observed spread gives an MDE of at
    most `seed_target` (a robustness row: TOST power 80 % at a true difference of zero), against the
    seeds it ran."""
    target = seed_target(claim)
    if target is None:
        return "– (no target)"
    if d.method != "paired" or d.se is None:
        return "n/a (" + ("one seed" if d.method == "paired" else "unpaired") + ")"
    if claim.direction == 0:
        return _met(seeds_for_tost(d.se * math.sqrt(d.n_a), margin_of(claim)), d.n_a)
    return _met(seeds_for_mde(d.se, d.n_a, target), d.n_a)


def lambda_seed_points(res: Results, ids: list[str], protocol: Any, axis: str, metric: str,
                       scale: float = 1.0) -> tuple[list, list[float], list[float]]:
    """(seed, lambda value, metric in display units) per done run of the lambda grid among `ids` (one
    regime); the seed is None for a run without one."""
    seeds: list = []
    xs: list[float] = []
    ys: list[float] = []
    concrete = res.resolve(metric, protocol)
    if concrete is None or axis not in res.runs.columns:
        return seeds, xs, ys
    for rid in [r for r in ids if same(res.runs.at[r, "study"], "lambda_grid")]:
        lam, v = res.runs.at[rid, axis], res.value(rid, concrete)
        if res.runs.at[rid, "status"] != "done" or is_null(lam) or not math.isfinite(v):
            continue
        seed = res.runs.at[rid, "seed"]
        seeds.append(None if is_null(seed) else int(seed))   # runs without a seed share one intercept
        xs.append(float(lam))
        ys.append(scale * v)
    return seeds, xs, ys


def _measure_r(res: Results, claim: Claim, ids: list[str], protocol: Any) -> Measured:
    """A lambda claim by its within-seed analysis (module docstring)."""
    sp = metric_spec(claim.metric)
    seeds, xs, ys = lambda_seed_points(res, ids, protocol, claim.correlation or "", claim.metric, sp.scale)
    fit, why = within_seed(seeds, xs, ys)
    if fit is None:
        return Measured(f"n/a ({why})", NOT_RUN if len(xs) < 3 else INCONCLUSIVE, no_effect=len(xs) >= 3)
    mde = _mde_text(mde_within_r(fit.n, fit.seeds), 2, f"{fit.n} runs on {fit.seeds} seeds")
    target = seed_target(claim)
    per_seed = max(2, round(fit.n / fit.seeds))
    seeds_txt = ("– (no target)" if target is None or target >= 1.0
                 else _met(seeds_for_within_r(target, per_seed), fit.seeds, " seeds"))
    slope = (f"; slope {fit.slope:+.3f} [{fit.slope_lo:+.3f}, {fit.slope_hi:+.3f}] {sp.label} per unit, "
             f"p {fit.p:.2g}")
    if fit.r_lo is None or fit.r_hi is None:
        return Measured(f"within-seed r = {fit.r:+.2f} [n/a] (n={fit.n}, {fit.seeds} seeds){slope}", INCONCLUSIVE,
                        mde, True, seeds=seeds_txt)
    lo, hi = fit.r_lo, fit.r_hi
    v = verdict(claim.direction, lo, hi, paper=claim.paper, decimals=claim.paper_decimals)
    excludes_zero = lo > 0 or hi < 0
    p_paper = p_r_against(fit.r, claim.paper, fit.n, fit.seeds) if claim.paper is not None else None
    text = (f"within-seed r = {fit.r:+.2f} [{lo:+.2f}, {hi:+.2f}]{' *' if excludes_zero else ''} "
            f"(n={fit.n}, {fit.seeds} seeds){slope}")
    return Measured(text, verdict_text(v, claim.direction, lo, hi, claim.paper, claim.paper_decimals), mde,
                    not excludes_zero, True, seeds_txt, _tests(zero=fit.p, paper=p_paper), rests_on(v, claim.direction))


def _measure_robust(claim: Claim, d: Diff, text: str, mde: str, seeds: str) -> Measured:
    """A robustness claim by TOST against +-margin (module docstring)."""
    if d.se is None or d.df is None or d.delta is None:
        return Measured(text, INCONCLUSIVE, mde, True, d.has_interval, seeds)
    margin = margin_of(claim)
    eq = tost(d.delta, d.se, d.df, margin)
    v = verdict(0, eq.lo, eq.hi, margin=margin)
    band = (f"{math.exp(eq.lo):.2f}, {math.exp(eq.hi):.2f}" if claim.log_ratio else f"{eq.lo:+.2f}, {eq.hi:+.2f}")
    text += (f"; {100 * (1 - 2 * TOST_ALPHA):g} % [{band}] against {margin_text(claim)}, TOST p {eq.p:.2g}")
    power = (f"TOST power {tost_power(d.se * math.sqrt(d.n_a), d.n_a, margin):.2f} at 0"
             if d.method == "paired" and d.n_a >= 2 else mde)
    return Measured(text, v, power, not d.significant, d.has_interval, seeds, _tests(tost=eq.p, harm=eq.p_harm),
                    rests_on(v, 0))


def measure(res: Results, claim: Claim, ids: list[str], protocol: Any) -> Measured:
    """Measured effect, verdict and MDE of one claim on the runs `ids` of its study in one regime."""
    sp = metric_spec(claim.metric)
    if res.resolve(claim.metric, protocol) is None:
        return Measured("n/a (metric not defined for this protocol)", NOT_RUN)
    if claim.correlation:
        return _measure_r(res, claim, ids, protocol)
    concrete = res.resolve(claim.metric, protocol)
    a, b = _select(res, ids, claim.row), _select(res, ids, claim.reference)
    va, vb = res.seed_values(a, concrete, sp.scale), res.seed_values(b, concrete, sp.scale)
    if not va or not vb:
        return _unmeasured(res, a if not va else b, concrete, "compared row" if not va else "reference row")
    if claim.log_ratio:
        va, vb = _logs(va), _logs(vb)
    why = _dropped_reason(res, a + b, list(claim.row) + list(claim.reference))
    d: Diff = compare(va, vb)
    text = ratio_text(d) if claim.log_ratio else d.text(sp.decimals)
    mde, seeds = _mde_text(d.mde, sp.decimals, d.reason or "no spread"), _seeds_text(claim, d)
    if why:
        return Measured(text + f"; setting dropped: {why}", NOT_TESTABLE, mde, interval=d.has_interval, seeds=seeds)
    why_blind = starved(res, a, claim.inputs)
    if why_blind and not d.significant:   # as for controls: an interval that excludes zero is never hidden
        return Measured(text, f"{BLIND}: {why_blind}", mde, True, d.has_interval, seeds)
    if claim.direction == 0:
        return _measure_robust(claim, d, text, mde, seeds)
    v = verdict(claim.direction, d.lo, d.hi, paper=claim.paper, decimals=claim.paper_decimals)
    p_paper = None
    if claim.paper is not None and d.se is not None and d.df and d.delta is not None:   # se 0: exact
        p_paper = (p_two_sided((d.delta - claim.paper) / d.se, d.df) if d.se > 0.0
                   else float(d.delta == claim.paper))
    return Measured(text, verdict_text(v, claim.direction, d.lo, d.hi, claim.paper, claim.paper_decimals), mde,
                    not d.significant, d.has_interval, seeds, _tests(zero=d.p, paper=p_paper),
                    rests_on(v, claim.direction))


def _logs(values: dict) -> dict:
    """log of each positive value (a ratio claim); a value at or below zero has no log and is left out."""
    return {k: math.log(v) for k, v in values.items() if v > 0.0}


def ratio_text(d: Diff) -> str:
    """A log-scale difference printed as the ratio row / reference: 'ratio 0.97 [0.91, 1.04] (n=3, paired)'."""
    if d.delta is None:
        return d.text(2)
    s = f"ratio {math.exp(d.delta):.2f}"
    if d.has_interval:
        s += f" [{math.exp(d.lo):.2f}, {math.exp(d.hi):.2f}]" + (" *" if d.significant else "")  # type: ignore[arg-type]
    return s + d.tag()


def _unmeasured(res: Results, rids: list[str], metric: str | None, side: str) -> Measured:
    """A row with no value on one side: 'not run' when that side has no finished run, else 'not measured'
    with the reason its runs recorded (e.g. no LPIPS weights on this machine)."""
    if not rids or not any(res.runs.at[r, "status"] == "done" for r in rids):
        return Measured(f"n/a ({side} not run)", NOT_RUN)
    reason = res.cell(rids, metric).reason or "no value recorded"
    return Measured(f"n/a ({side}: {reason})", f"{NOT_MEASURED}: {reason}")


def holm_qualify(rows: list[ClaimRow]) -> int:
    """Holm across every test of every measured row (`Measured.tests`: the family is fixed by the rules,
    not by the verdicts); a verdict is qualified '(fails Holm)' when a hypothesis it rejects has a Holm p
    above ALPHA, and '(after a second look)' when the row is `looked` (a cell of it came from a grid that
    got seeds after a look at its results). Sets each row's p / Holm p (those its verdict rests on, else
    its zero / TOST test) in place; returns the family's size."""
    measured = [(r.measured, r.looked) for r in rows if r.measured is not None]
    family = [(m, name, p) for m, _looked in measured for name, p in m.tests.items()]
    adjusted = {(id(m), name): hp for (m, name, _p), hp in zip(family, holm([p for _m, _n, p in family]))}
    for m, looked in measured:
        base = m.verdict.split(":", 1)[0]
        rests = m.rests if base in REJECTING else ()
        shown = [n for n in rests if n in m.tests] or [n for n in ("zero", "tost") if n in m.tests][:1]
        if shown:
            m.p = max(m.tests[n] for n in shown)
            m.holm_p = max(adjusted[(id(m), n)] for n in shown)
        if base not in REJECTING:
            continue
        fails = any(adjusted.get((id(m), n), 1.0) > ALPHA for n in rests)
        notes = ([FAILS_HOLM] if fails else []) + ([SECOND_LOOK] if looked else [])
        m.verdict = qualified(m.verdict, notes)
    return len(family)


def _p_text(m: Measured) -> str:
    if m.p is None:
        return "–"
    return f"{m.p:.2g} ({m.holm_p:.2g})" if m.holm_p is not None else f"{m.p:.2g}"


@dataclass
class ClaimRow:
    """One claim in one regime (regime None: the claim's study did not run): its measurement and the
    control that guards it there."""
    claim: Claim
    regime: Regime | None = None
    label: str = "–"
    guard: Guard | None = None
    measured: Measured | None = None
    looked: bool = False   # a cell of the row came from a grid that got seeds after a look at its results


def regime_cell(regime: Regime, protocol: Any, kinds: dict[str, str] | None) -> str:
    """The Regime column: the declared regime's name with its scene, else the regime in full."""
    d = declared(regime)
    if d is None:
        return regime_label(regime, protocol, kinds)
    return f"{d.name}: " + regime_label(regime, protocol, kinds, name=False).split(", ", 1)[0]


def claim_rows(res: Results, claims: list[Claim] | None = None,
               later: frozenset[str] = frozenset(), kinds: dict[str, str] | None = None) -> list[ClaimRow]:
    """One row per claim and regime its study ran in (one row without a regime when it did not run at
    all), measured, guarded in its regime and Holm-qualified (`holm_qualify`) together. `later`: the run
    ids of the cells whose grid got seeds after a look at its results (a row with one is qualified)."""
    claims = study_table.paper_claims() if claims is None else claims
    marks = regime_marks(res)
    rows: list[ClaimRow] = []
    for c in claims:
        ids = res.run_ids(study=c.study)
        groups = regime_groups(res, ids) if ids else []
        if not groups:
            rows.append(ClaimRow(c))
        for regime, pr, gids in groups:
            m = measure(res, c, gids, pr)
            guard = Guard(f"none needed: {c.unguarded}", None) if c.unguarded else claim_guard(marks, c.key, regime)
            # blind replaces only the verdicts whose interval includes zero (a robustness "reproduced" too,
            # since a blind study also shows no change): an interval that excludes zero shows the mechanism
            # whatever the controls say; a verdict already blind (no input) keeps its own reason
            if guard.blind and m.no_effect and not m.verdict.startswith(BLIND):
                m.verdict = guard.blind
            rows.append(ClaimRow(c, regime, regime_cell(regime, pr, kinds), guard, m, bool(later & set(gids))))
    holm_qualify(rows)
    return rows


def claims_table(res: Results, claims: list[Claim] | None = None, later: frozenset[str] = frozenset(),
                 kinds: dict[str, str] | None = None, rows: list[ClaimRow] | None = None) -> list[Table]:
    """One row per claim and regime the claim's study ran in ('not run' when it did not run at all);
    no table when none of the claims' studies ran. `later`: the run ids of the cells whose grid got seeds
    after a look at its results; `kinds`: scene name -> 'synthetic' / 'real'; `rows`: `claim_rows` already made."""
    claims = study_table.paper_claims() if claims is None else claims
    if not any(res.run_ids(study=c.study) for c in claims):
        return []
    rows = claim_rows(res, claims, later, kinds) if rows is None else rows
    k = sum(len(r.measured.tests) for r in rows if r.measured is not None)
    out = []
    for r in rows:
        c, m = r.claim, r.measured
        if m is None or r.guard is None:
            out.append(not_run_row(c))
            continue
        out.append(Row([c.text, c.source, r.label, r.guard.text],
                       [Cell(text=paper_text(c)), Cell(text=m.text), Cell(text=m.mde), Cell(text=m.verdict),
                        Cell(text=m.seeds), Cell(text=_p_text(m))]))
    return [Table("paper_claims", "Paper claims", claims_caption(k), ["Claim", "Paper source", "Regime", "Guarded by"],
                  CLAIM_COLUMNS, out, section="claims")]
