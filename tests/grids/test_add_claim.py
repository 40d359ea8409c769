"""Adding a claim on a new study is one declaration plus its grid file (docs/grids.md, "Adding a claim").

The addition is written into a temporary folder, as a user would write it: one Python file with one
`Study(...)` (its axes, reference, grid and claim) and one grid file. The declaration joins the study
table's `DECLARED` (what appending it to methods/gaussiands/study_table.py does), and nothing else is
edited: the claims plan, the grid check, the claims table, the matrix and the page read it from there.
The page is built, as `gsbench publish --page` builds it, from a tiny store of six cells (the published
control_sem cells re-labelled as the new study's), and the new claim's row must be on it, measured.
"""
from __future__ import annotations

import copy
import importlib.util
import textwrap
from pathlib import Path

from paths import REPO_ROOT

from gsbench.grids.claims_plan import plan_grids
from gsbench.grids.store import Published
from gsbench.grids.store_format import read_record
from gsbench.methods.gaussiands import study_table
from gsbench.reports.claims_page import build_page

STORE_CELLS = REPO_ROOT / "results" / "cpu" / "control_sem-cpu"
CLAIM_TEXT = "lambda_sem = 5 raises mIoU over lambda_sem = 0"

# the whole addition: the declaration, then the grid file (the how-to in docs/grids.md shows the same two)
DECLARATION = '''from pathlib import Path

from gsbench.methods.gaussiands.study_types import Claim, Study, column

SEM = column("gaussiands.lambdas.sem")
STUDY = Study("sem_weight", "Semantic loss weight", ("gaussiands.lambdas.sem",), {"gaussiands.lambdas.sem": 5.0},
              "lambda_sem = 5 (the paper's default)",
              claims_grids=(str(Path(__file__).with_name("sem_weight-cpu.yaml")),), claims=(
                  Claim("sem_weight_miou", "lambda_sem = 5 raises mIoU over lambda_sem = 0",
                        "a test's own claim (no paper table)", "miou", +1, None, "no number given",
                        {SEM: 5.0}, {SEM: 0.0}),))
'''
GRID = '''study: sem_weight
description: lambda_sem 0 / 5 with GT masks
base:
  method: gaussiands
  preset: cpu-medium
  set:
    priors.masks.provider: gt
scenes: [tabletop-medium]
seeds: [0, 1, 2]
axes:
  gaussiands.lambdas.sem: [0.0, 5.0]
'''


def _write_addition(folder: Path) -> list[Path]:
    """The addition's files, written into `folder`."""
    folder.mkdir(parents=True)
    (folder / "sem_weight_study.py").write_text(DECLARATION, encoding="utf-8")
    (folder / "sem_weight-cpu.yaml").write_text(GRID, encoding="utf-8")
    return sorted(p for p in folder.rglob("*") if p.is_file())


def _declared_study(path: Path) -> study_table.Study:
    spec = importlib.util.spec_from_file_location("sem_weight_study", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.STUDY


def _tiny_store() -> list[Published]:
    """The six published control_sem cells (lambda_sem 0 / 5, seeds 0-2), re-labelled as sem_weight's."""
    out = []
    for p in sorted(STORE_CELLS.glob("*.json")):
        rec = copy.deepcopy(read_record(p))
        rec["grid"] = "sem_weight-cpu"       # the store's grid name; results and config keep their axis values
        for part in (rec, rec["results"], rec["config"]):
            part["study"] = "sem_weight"
        out.append(Published(p, rec))
    return out


def _rows(page_text: str, text: str) -> list[str]:
    """The page's table rows of one claim: its row of the claim x regime matrix, then of the claims table."""
    return [ln for ln in page_text.splitlines() if ln.startswith(f"| {text} |")]


def test_one_declaration_and_one_grid_file_add_a_claim_row(tmp_path, monkeypatch):
    files = _write_addition(tmp_path / "addition")
    assert [p.name for p in files] == ["sem_weight-cpu.yaml", "sem_weight_study.py"]   # 2 files touched
    cells = _tiny_store()
    assert len(cells) == 6

    before = build_page(cells, [], plan_grids(), "claims_figures")
    assert _rows(before.text, CLAIM_TEXT) == []

    shipped_claim_grids, shipped_claims = len(study_table.claim_grids()), len(study_table.paper_claims())
    monkeypatch.setattr(study_table, "DECLARED", (*study_table.DECLARED, _declared_study(files[1])))
    grids = plan_grids()
    assert [g.name for g in grids][shipped_claim_grids] == "sem_weight-cpu"   # after the shipped claim grids
    page = build_page(cells, [], grids, "claims_figures")
    rows = _rows(page.text, CLAIM_TEXT)
    assert len(rows) == 2, "the new claim needs a row in the matrix and one in the claims table"
    matrix, table = rows
    assert matrix.endswith("| reproduced |")              # its own regime's column: GT masks, not a declared one
    assert "| a test's own claim (no paper table) |" in table and "(n=3, paired)" in table
    assert "| not run |" not in table
    assert "| sem_weight-cpu | sem_weight | 3 | 6 | 6 |" in page.text.splitlines()
    # the shipped claims keep their rows, 'study not run' in a store that holds none of their cells
    assert len(_rows(page.text, "scale-shift beats raw L1 depth (PSNR)")) == 2
    assert f"Claims ({shipped_claims + 1} rows, all regimes)" in page.text


def test_the_how_to_declaration_is_one_study_with_one_claim():
    """The declaration docs/grids.md shows ("Adding a claim") is valid: one study with the test's claim,
    a shipped grid name in place of the test's path."""
    text = (REPO_ROOT / "docs" / "grids.md").read_text(encoding="utf-8")
    section = text[text.index("## Adding a claim"):text.index("## Seeds")]
    start = section.index("```python") + len("```python")
    code = textwrap.dedent(section[start:section.index("```", start)]).strip().rstrip(",")
    names = {k: getattr(study_table, k) for k in ("Study", "Claim", "gap", "column")}
    shown = eval(code, names)  # noqa: S307  (the docs' own snippet)
    assert shown.name == "sem_weight" and shown.claims_grids == ("sem_weight-cpu",)
    assert [c.text for c in shown.claims] == [CLAIM_TEXT]
    assert shown.claims[0].paper == 51.8            # 64.10 - 12.30 as printed
    assert shown.claims[0].row == {"axis.gaussiands.lambdas.sem": 5.0}
