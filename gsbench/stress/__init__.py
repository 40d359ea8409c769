"""The numerical stress battery behind `gsbench stress`.

Each case builds an extreme input, runs one component in float32 (the precision training uses)
and compares it with the same computation in float64, checking that outputs and gradients are
finite. One row per case: component, case, max abs / relative error, finite outputs, finite
gradients, pass/fail. Components whose code is absent from this build are listed as failed rows
with the reason, never as passed.

core.py holds the types, comparisons and the runner; each cases_*.py module builds the cases of
one part. The loader list below fixes the order of the table.
"""
from __future__ import annotations

from typing import Callable, Optional

from gsbench.stress.cases_depth import depth_solve_cases
from gsbench.stress.cases_losses import autoencoder_cases, loss_cases, stiff_lambda_cases
from gsbench.stress.cases_metrics import metric_cases
from gsbench.stress.cases_render import available_backends, projection_cases, render_cases
from gsbench.stress.core import Case, CaseResult, _result, all_finite, compare, run_case, scaled_err

__all__ = ["Case", "CaseResult", "all_cases", "all_finite", "available_backends", "compare", "run_case",
           "scaled_err", "_result"]

# Loaders import their component inside, so that a component absent from a build becomes a failed row.
_EXTRA_CASE_LOADERS: list[Callable[[], list[Case]]] = [
    projection_cases, depth_solve_cases, loss_cases, stiff_lambda_cases, autoencoder_cases, metric_cases,
]


def all_cases(components: Optional[list[str]] = None) -> tuple[list[Case], list[CaseResult]]:
    """Every case of this build (render cases per backend first), plus failed rows for absent components."""
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
