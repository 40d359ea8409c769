"""The "paper claims" table: each claim of the paper's ablation section, the paper's number, gsbench's
measured effect with its 95 % interval, the minimum detectable effect (MDE) at its n, and a verdict
that follows only from that interval.

Why a data table: the paper's numbers live in one place (PAPER_CLAIMS, each with the section and
table or figure it comes from), and the verdict rules are the same for every row. Interval and
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
- not testable: the resolver dropped the setting the claim is about (e.g. no depth prior).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from gsbench.reports.ablations import _covered, run_dropped
from gsbench.reports.controls import blind_claims
from gsbench.reports.data import Results, same

from gsbench.reports.spec import (AX_FORMULATION, AX_LATENT, AX_LOSSES, AX_NOISE_SEVERITY, AX_NOISE_TYPE,  # isort: skip
                                  AX_ORDERING, metric_spec)
from gsbench.reports.stats import Diff, compare, mde_r, pearson, pearson_interval
from gsbench.reports.studies import PROTOCOL_SHORT, _get, scene_protocols
from gsbench.reports.sweeps import lambda_points
from gsbench.reports.table import Cell, Column, Row, Table

REPRODUCED, OPPOSITE, INCONCLUSIVE, NOT_RUN, NOT_TESTABLE = (
    "reproduced", "opposite", "inconclusive", "not run", "not testable")
SMALLER, NOT_REPRODUCED = "smaller than claimed", "not reproduced"
ROBUST_MARGIN_DB = 0.5  # gsbench's equivalence margin for "PSNR is robust" (dB), not the paper's
MAX = "max"             # selector value: the highest value of that axis among the study's runs


@dataclass(frozen=True)
class Claim:
    key: str
    text: str                  # the claim in words
    source: str                # section and table / figure of the paper
    study: str
    metric: str                # logical metric ('miou' resolves per protocol)
    direction: int             # +1 / -1: the paper's sign of (row - reference); 0: no effect claimed
    paper: float | None        # the paper's number (difference or r) in display units, None = none given
    paper_note: str = ""
    row: dict = field(default_factory=dict)        # axis -> value of the compared row
    reference: dict = field(default_factory=dict)  # axis -> value of the row it is compared with
    correlation: str | None = None                 # lambda axis: Pearson r with the metric instead


_ALL = {AX_LOSSES[0]: True, AX_LOSSES[1]: True, AX_LOSSES[2]: True}
_NONE = {AX_LOSSES[0]: False, AX_LOSSES[1]: False, AX_LOSSES[2]: False}
_ABL = "Sec. Ablation Studies"
PAPER_CLAIMS: list[Claim] = [
    Claim("depth_ss_raw_psnr", "scale-shift beats raw L1 depth (PSNR)", f"{_ABL}, Table tab-depth-align (bench)",
          "depth_formulation", "psnr", +1, 24.81 - 21.31, "24.81 vs 21.31 dB",
          {AX_FORMULATION: "scale_shift"}, {AX_FORMULATION: "raw_l1"}),
    Claim("depth_mm_raw_psnr", "min-max beats raw L1 depth (PSNR)", f"{_ABL}, Table tab-depth-align (bench)",
          "depth_formulation", "psnr", +1, 23.93 - 21.31, "23.93 vs 21.31 dB",
          {AX_FORMULATION: "minmax"}, {AX_FORMULATION: "raw_l1"}),
    Claim("depth_ss_mm_psnr", "scale-shift beats min-max depth (PSNR)", f"{_ABL}, Table tab-depth-align (bench)",
          "depth_formulation", "psnr", +1, 24.81 - 23.93, "24.81 vs 23.93 dB",
          {AX_FORMULATION: "scale_shift"}, {AX_FORMULATION: "minmax"}),
    Claim("depth_ss_raw_mbiou", "scale-shift beats raw L1 depth (mBIoU)", f"{_ABL}, Table tab-depth-align (bench)",
          "depth_formulation", "mbiou", +1, 91.99 - 59.69, "91.99 vs 59.69 %",
          {AX_FORMULATION: "scale_shift"}, {AX_FORMULATION: "raw_l1"}),
    Claim("depth_ss_mm_mbiou", "scale-shift beats min-max depth (mBIoU)", f"{_ABL}, Table tab-depth-align (bench)",
          "depth_formulation", "mbiou", +1, 91.99 - 89.21, "91.99 vs 89.21 %",
          {AX_FORMULATION: "scale_shift"}, {AX_FORMULATION: "minmax"}),
    Claim("loss_depth_psnr", "L_depth alone raises PSNR over no auxiliary loss", f"{_ABL}, Table tab-ablation (bench)",
          "loss_subsets", "psnr", +1, 22.46 - 16.02, "22.46 vs 16.02 dB",
          {**_NONE, AX_LOSSES[0]: True}, _NONE),
    Claim("loss_ds_miou", "L_ds alone raises mIoU over no auxiliary loss", f"{_ABL}, Table tab-ablation (bench)",
          "loss_subsets", "miou", +1, 84.40 - 47.10, "84.40 vs 47.10 %",
          {**_NONE, AX_LOSSES[2]: True}, _NONE),
    Claim("loss_all_psnr", "all three losses raise PSNR over none", f"{_ABL}, Table tab-ablation (bench)",
          "loss_subsets", "psnr", +1, 24.81 - 16.02, "24.81 vs 16.02 dB", _ALL, _NONE),
    Claim("loss_all_miou", "all three losses raise mIoU over none", f"{_ABL}, Table tab-ablation (bench)",
          "loss_subsets", "miou", +1, 96.97 - 47.10, "96.97 vs 47.10 %", _ALL, _NONE),
    Claim("loss_ds_mbiou", "adding L_ds to L_depth + L_tv raises mBIoU (boundary leakage)",
          f"{_ABL} (loss decomposition) and Sec. Boundary-Aware Semantic Segmentation", "loss_subsets", "mbiou", +1,
          None, "no number given", _ALL, {**_ALL, AX_LOSSES[2]: False}),
    Claim("ordering_pose_random", "pose-nearest ordering raises adjacent mask IoU over random",
          f"{_ABL}, Table tab-ordering (five 3D-OVS scenes)", "ordering", "ordering_adjacent_mask_iou_strict", +1,
          53.21 - 33.92, "53.21 vs 33.92 %", {AX_ORDERING: "pose"}, {AX_ORDERING: "random"}),
    Claim("ordering_pose_filename", "pose-nearest ordering raises adjacent mask IoU over filename order",
          f"{_ABL}, Table tab-ordering (five 3D-OVS scenes)", "ordering", "ordering_adjacent_mask_iou_strict", +1,
          53.21 - 50.85, "53.21 vs 50.85 %", {AX_ORDERING: "pose"}, {AX_ORDERING: "filename"}),
    Claim("lambda_depth_r", "lambda_depth correlates negatively with mIoU",
          f"{_ABL} (sensitivity), Fig. fig-lambda-sweep", "lambda_grid", "miou", -1, -0.89, "Pearson r",
          correlation="axis.gaussiands.lambdas.depth"),
    Claim("lambda_sem_r", "lambda_sem correlates positively with mIoU",
          f"{_ABL} (sensitivity), Fig. fig-lambda-sweep", "lambda_grid", "miou", +1, 0.69, "Pearson r",
          correlation="axis.gaussiands.lambdas.sem"),
    Claim("latent_16_3", "mIoU rises from d = 3 to d = 16", f"{_ABL}, Table tab-dims (waldo_kitchen)",
          "latent_dim", "miou", +1, 62.83 - 61.42, "62.83 vs 61.42 %",
          {"method": "gaussiands", AX_LATENT: 16}, {"method": "gaussiands", AX_LATENT: 3}),
    Claim("latent_32_16", "mIoU falls from d = 16 to d = 32", f"{_ABL}, Table tab-dims (waldo_kitchen)",
          "latent_dim", "miou", -1, 61.32 - 62.83, "61.32 vs 62.83 %",
          {"method": "gaussiands", AX_LATENT: 32}, {"method": "gaussiands", AX_LATENT: 16}),
    Claim("noise_motion_blur", "motion blur on the depth prior lowers PSNR (the most of the four kinds)",
          "Sec. Multi-view 3D Reconstruction (robustness), Fig. fig-noise", "depth_noise", "psnr", -1, None,
          "figure only, no number", {AX_NOISE_TYPE: "motion_blur", AX_NOISE_SEVERITY: MAX},
          {AX_NOISE_TYPE: None, AX_NOISE_SEVERITY: 0}),
    *[Claim(f"noise_{kind}", f"PSNR is robust to {kind.replace('_', '-')} noise on the depth prior",
            "Sec. Multi-view 3D Reconstruction (robustness), Fig. fig-noise", "depth_noise", "psnr", 0, None,
            f"figure only: 'remarkably robust'; gsbench margin +-{ROBUST_MARGIN_DB} dB",
            {AX_NOISE_TYPE: kind, AX_NOISE_SEVERITY: MAX}, {AX_NOISE_TYPE: None, AX_NOISE_SEVERITY: 0})
      for kind in ("gaussian", "poisson", "salt_pepper")],
]


def verdict(direction: int, lo: float | None, hi: float | None, paper: float | None = None,
            margin: float = ROBUST_MARGIN_DB) -> str:
    """The verdict of one claim from the interval [lo, hi] of (row - reference), or of r; with the
    paper's number `paper` the verdict is sized against it (module docstring)."""
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
    short = b < abs(paper)  # the whole interval lies short of the paper's value
    if a > 0.0:
        return SMALLER if short else REPRODUCED
    return NOT_REPRODUCED if short else INCONCLUSIVE


def verdict_text(v: str, direction: int, lo: float | None, hi: float | None, paper: float | None,
                 decimals: int) -> str:
    """The verdict with, when the interval lies short of the paper's number, the largest effect on the
    paper's side it still allows ("at most +0.14, paper +37.30")."""
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
    """One row's measurement: the effect text, the verdict (with its bound), the MDE text."""
    text: str
    verdict: str
    mde: str = "–"


def _mde_text(mde: float | None, decimals: int, why: str) -> str:
    return f"{mde:.{decimals}f}" if mde is not None else f"n/a ({why})"


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
            return Measured(f"n/a ({why})", NOT_RUN if len(xs) < 3 else INCONCLUSIVE, mde)
        ci = pearson_interval(r, len(xs))
        if ci is None:
            return Measured(f"r = {r:+.2f} [n/a: {len(xs)} runs, need 4] (n={len(xs)})", INCONCLUSIVE, mde)
        v = verdict(claim.direction, *ci, paper=claim.paper)
        mark = " *" if (ci[0] > 0 or ci[1] < 0) else ""
        return Measured(f"r = {r:+.2f} [{ci[0]:+.2f}, {ci[1]:+.2f}]{mark} (n={len(xs)})",
                        verdict_text(v, claim.direction, *ci, claim.paper, 2), mde)
    ids = res.run_ids(study=claim.study, scene=scene, protocol=protocol)
    a, b = _select(res, ids, claim.row), _select(res, ids, claim.reference)
    va, vb = res.seed_values(a, concrete, sp.scale), res.seed_values(b, concrete, sp.scale)
    if not va or not vb:
        return Measured("n/a (" + ("compared row" if not va else "reference row") + " not run or not evaluated)",
                        NOT_RUN)
    why = _dropped_reason(res, a + b, list(claim.row) + list(claim.reference))
    d: Diff = compare(va, vb)
    text = d.text(sp.decimals)
    mde = _mde_text(d.mde, sp.decimals, d.reason or "no spread")
    if why:
        return Measured(text + f"; setting dropped: {why}", NOT_TESTABLE, mde)
    v = verdict(claim.direction, d.lo, d.hi, paper=claim.paper)
    return Measured(text, verdict_text(v, claim.direction, d.lo, d.hi, claim.paper, sp.decimals), mde)


def claims_table(res: Results, claims: list[Claim] | None = None) -> list[Table]:
    """One row per claim and scene the claim's study ran on ('not run' when it did not run at all);
    no table when none of the claims' studies ran."""
    claims = PAPER_CLAIMS if claims is None else claims
    if not any(res.run_ids(study=c.study) for c in claims):
        return []
    blind = blind_claims(res)
    rows = []
    for c in claims:
        ids = res.run_ids(study=c.study)
        pairs = scene_protocols(res, ids) if ids else []
        paper = (f"{c.paper:+.2f}" if c.paper is not None else "–") + (f" ({c.paper_note})" if c.paper_note else "")
        if not pairs:
            rows.append(Row([c.text, c.source, "–"], [Cell(text=paper), Cell(text="study not run"), Cell(text="–"),
                                                      Cell(text=NOT_RUN)]))
            continue
        for sc, pr in pairs:
            m = measure(res, c, sc, pr)
            # blind replaces only the verdicts that read an absence of effect: an interval that excludes
            # zero shows the mechanism whatever the control says
            if c.key in blind and m.verdict.split(":")[0] in (NOT_REPRODUCED, INCONCLUSIVE):
                m.verdict = blind[c.key]
            rows.append(Row([c.text, c.source, f"{sc} ({PROTOCOL_SHORT.get(pr, pr)})"],
                            [Cell(text=paper), Cell(text=m.text), Cell(text=m.mde), Cell(text=m.verdict)]))
    cols = [Column("paper", "Paper", "Paper"), Column("measured", "gsbench [95 % CI] (n)", "gsbench [95\\% CI] (n)"),
            Column("mde", "MDE", "MDE"), Column("verdict", "Verdict", "Verdict")]
    cap = ("Claims of the paper's ablation section against gsbench's measurements: effect = compared row minus "
           "reference row (display units; PSNR in dB, IoU in %), or Pearson r for the lambda claims, with its 95 % "
           "interval (t interval paired by seed, else Welch; Fisher z for r). MDE = the smallest true effect this "
           "design detects (two-sided 5 %, 80 % power) from the observed spread at its n. Verdict, for a claim "
           "with a number: reproduced (interval excludes zero on the paper's side and reaches the paper's value), "
           "smaller than claimed (excludes zero, lies short of the paper's value), not reproduced (contains zero, "
           "lies short of the paper's value; the largest compatible effect is printed), opposite (excludes zero on "
           "the other side), inconclusive (contains zero and the paper's value, or one seed); without a number "
           "only the side of zero counts; blind = not reproduced or inconclusive while the claim's positive control "
           "ran and showed no marked effect (table claims_controls); robustness claims use a "
           f"+-{ROBUST_MARGIN_DB} dB margin chosen by gsbench; not run = no runs.")
    return [Table("paper_claims", "Paper claims", cap, ["Claim", "Paper source", "Scene"], cols, rows,
                  section="claims")]
