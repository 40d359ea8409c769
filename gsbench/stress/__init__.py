"""The numerical stress battery behind `gsbench stress`.

Each case builds an extreme input, runs one component in float32 (the precision training uses)
and compares it with the same computation in float64, checking that outputs and gradients are
finite. One row per case: component, case, max abs / relative error, finite outputs, finite
gradients, pass/fail. Components whose code is absent from this build are listed as failed rows
with the reason, never as passed.

core.py holds the types, comparisons and registry; the cases_*.py modules register their cases
in import order (which is the order of the table).
"""
from __future__ import annotations

from typing import Optional

from gsbench.stress.core import (_EXTRA_CASE_LOADERS, Case, CaseResult, _result, all_finite, compare, run_case,
                                 scaled_err)
from gsbench.stress.cases_render import available_backends, render_cases
from gsbench.stress import cases_depth, cases_losses, cases_metrics  # noqa: F401  (import registers the cases)

__all__ = ["Case", "CaseResult", "all_cases", "all_finite", "available_backends", "compare", "run_case",
           "scaled_err", "_result", "_EXTRA_CASE_LOADERS"]


def all_cases(components: Optional[list[str]] = None) -> tuple[list[Case], list[CaseResult]]:
    """Every case of this build, plus failed rows for components whose code is absent.

    Reads the registry through this package's name so that a test can extend it with monkeypatch."""
    cases = render_cases(available_backends())
    skipped: list[CaseResult] = []
    for loader in _EXTRA_CASE_LOADERS:
        try:
            cases.extend(loader())
        except ImportError as e:
            skipped.append(CaseResult(loader.__name__.replace("_cases", ""), "(all)", passed=False,
                                      note=f"skipped: component not importable ({e})"))
    if components:
        cases = [c for c in cases if any(c.component.startswith(p) for p in components)]
        skipped = [s for s in skipped if any(s.component.startswith(p) for p in components)]
    return cases, skipped
