"""The caption of the paper-claims table (reports/claims_table.py): what each column means and how each
verdict follows from its interval, in the words the page prints."""
from __future__ import annotations

from gsbench.methods.gaussiands.study_table import ROBUST_MARGIN_DB
from gsbench.reports.claims_tests import TOST_ALPHA
from gsbench.train.losses import EDGE_FLOOR


def claims_caption(k: int) -> str:
    """The paper-claims table's caption: how each column and verdict is computed, with the Holm family's size k."""
    return ("Claims of the paper's main tables and ablation section against gsbench's measurements: effect = "
            "compared row minus reference row (display units; PSNR in dB, IoU in %; a ratio claim, such as FPS, "
            "compares logs and prints the ratio compared / reference), with its 95 % interval (t interval paired on "
            "the "
            "seeds both rows ran, a dropped seed is named; Welch when they share none). Lambda claims: the "
            "within-seed Pearson r (seed fixed effects: lambda and the metric centred within each seed; Fisher z "
            "on n - seeds - 2) and the fixed-effects slope with its t interval. MDE = the smallest true effect "
            "this design detects (two-sided 5 % t test, 80 % power, exact noncentral t; for r, Fisher z) from the "
            "observed spread at its n. Paper numbers are compared at the paper's decimals. Verdict, for a claim "
            "with a number: reproduced (interval excludes zero on the paper's side and contains the paper's "
            "value), larger than claimed (excludes zero, lies wholly beyond the paper's value), smaller than "
            "claimed (excludes zero, lies wholly short of it), not reproduced (contains zero, lies wholly short "
            "of the paper's value; the largest compatible effect is printed), opposite (excludes zero on the "
            "other side), inconclusive (contains zero and the paper's value, or one seed); without a number only "
            "the side of zero counts. Robustness claims are an equivalence test: TOST at "
            f"{100 * TOST_ALPHA:g} % a side against +-{ROBUST_MARGIN_DB} dB, or the margin the row names (margins "
            "chosen by gsbench), "
            f"reproduced when both one-sided tests reject (the {100 * (1 - 2 * TOST_ALPHA):g} % interval lies "
            "inside the margin), opposite when that interval lies wholly beyond -margin; their MDE column gives "
            "TOST's power at a true difference of zero. Regime = where the row's cells ran (scene, training views, "
            "preset, prior providers); Guarded by = the positive control marked in that regime (table "
            "claims_controls; a control may use the exact version of the claim's depth prior, and says so). "
            "blind = any verdict whose interval includes zero (robustness 'reproduced' too) while no control of "
            "the claim is marked in its regime ('no control in this regime' when none ran there), or while the "
            "compared row lacked what the mechanism acts on (for L_ds: an "
            f"edge map E_d marking under {100 * EDGE_FLOOR:g} % of the pixels); not run = no runs; "
            "not measured = the runs finished but recorded no value (their reason is printed, e.g. no LPIPS weights "
            "on this machine); Guarded by 'none needed' = a timing, which no mechanism switches off. "
            "Holm: every row's tests form one family, fixed by the rules before any verdict (no effect, and the "
            "paper's value where it gives one; for robustness TOST and a drop beyond the margin), "
            f"{k} tests in all, corrected together by Holm at 5 %. p (Holm p) = the p-value of the hypothesis the "
            "row's verdict rejects (the larger of the two for 'larger' / 'smaller than claimed'; no effect, or "
            "TOST, where the verdict rejects nothing) and its Holm-adjusted value. A verdict that "
            "rejects a hypothesis whose Holm p exceeds 0.05 reads '(fails Holm)'; one from a grid whose seeds were "
            "extended after a look at its results reads '(after a second look)' (docs/grids.md, \"Seeds\"). "
            "Seeds for the MDE = the seed rule: how many paired seeds this row's observed spread needs for an MDE "
            "of at most half the paper's effect (robustness: TOST power 80 % at a true difference of zero; lambda "
            "claims: the seeds, each adding its lambda settings as runs, at which the smallest detectable "
            "within-seed |r| is half the paper's), 'met' when it ran that many.")
