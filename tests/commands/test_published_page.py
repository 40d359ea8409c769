"""docs/claims.md and the README's claims block are generated from the published store results/cpu:
regenerated here and compared with the committed files, so a hand-edited number or a store, plan or
claim changed without regenerating the page fails CI. Plus: the check catches an edited number in a
copy, and the same store gives byte-identical pages and figures."""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from paths import REPO_ROOT

from gsbench.cli import main
from gsbench.grids.claims_plan import plan_grids
from gsbench.grids.store import Published, classify, read_store
from gsbench.reports.claims_page import README_BEGIN, README_END, build_page, check_page, figure_folder, write_page

PAGE = REPO_ROOT / "docs" / "claims.md"
README = REPO_ROOT / "README.md"
STORE = REPO_ROOT / "results" / "cpu"
NUMBER = re.compile(r"[+-]\d+\.\d+")
REGENERATE = "gsbench publish --page docs/claims.md --from results/cpu --readme README.md"


@pytest.fixture(scope="module")
def committed_page():
    grids = plan_grids()
    current, stale = classify(read_store(STORE), grids)
    return build_page(current, stale, grids, figure_folder(PAGE).name)


def test_committed_page_is_the_stores(committed_page):
    folder = figure_folder(PAGE)
    names = [p.name for p in folder.glob("dose_*.png")] if folder.is_dir() else []
    diff = check_page(committed_page, PAGE.read_text(encoding="utf-8"), README.read_text(encoding="utf-8"), names)
    assert diff == [], f"docs/claims.md or the README block differ from results/cpu; run `{REGENERATE}`:\n" + \
        "\n".join(diff[:20])


def _edit_a_number(page: str) -> tuple[str, str, str]:
    """(edited page, the line as committed, the line as edited): the first signed number of a table
    row gets another last digit."""
    line = next(ln for ln in page.splitlines() if ln.startswith("| ") and NUMBER.search(ln))
    num = NUMBER.search(line).group(0)
    edited_line = line.replace(num, num[:-1] + str((int(num[-1]) + 1) % 10), 1)
    return page.replace(line, edited_line, 1), line, edited_line


def test_a_hand_edited_number_is_caught(committed_page, tmp_path, capsys):
    page = PAGE.read_text(encoding="utf-8")
    edited, line, edited_line = _edit_a_number(page)
    copy_path = tmp_path / "claims.md"
    copy_path.write_text(edited, encoding="utf-8")
    assert check_page(committed_page, copy_path.read_text(encoding="utf-8")) == ["-" + edited_line, "+" + line]
    readme = README.read_text(encoding="utf-8")
    block = readme[readme.index(README_BEGIN):readme.index(README_END)]
    edited_readme = readme.replace(block, block.replace(" cells published", "1 cells published", 1))
    assert any(d.startswith("- README:") for d in check_page(committed_page, page, edited_readme))
    # the command line's --check: the edited copy fails with the line, the committed page passes
    assert main(["publish", "--page", str(copy_path), "--from", str(STORE), "--check"]) == 1
    assert "-" + edited_line in capsys.readouterr().out
    assert main(["publish", "--page", str(PAGE), "--from", str(STORE), "--readme", str(README), "--check"]) == 0
    assert "matches the store" in capsys.readouterr().out


def _swept_cells() -> list[Published]:
    """Four cells of a latent-d study (d = 3 and 8, seeds 0 and 1), so the page has a dose-response
    figure to draw (made up here: the page builder, not the numbers, is under test)."""
    out = []
    for d in (3, 8):
        for seed in (0, 1):
            rid = f"{d:02d}{seed:02d}" + "ab" * 6
            grid = {"semantic.latent_dim": d}
            results = {"run_id": rid, "method": "gaussiands", "scene": "tabletop-medium-0", "seed": seed,
                       "study": "latent_dim", "grid": grid, "protocol": "3dovs", "protocols": ["3dovs"],
                       "status": "done", "metrics": {"miou_3dovs": 0.4 + 0.01 * d + 0.005 * seed, "psnr": 20.0}}
            rec = {"grid": "latent_dim-cpu", "study": "latent_dim", "run_id": rid, "numerics_version": 1,
                   "scene_fingerprint": "f" * 64, "cell": {"method": "gaussiands", "seed": seed, "axes": grid},
                   "config": {"method": "gaussiands", "seed": seed, "gaussiands": {"latent_dim": d}},
                   "results": results, "train_summary": {}, "provenance": {"cpu_model": "a CPU", "numba": "0"}}
            out.append(Published(Path(f"{rid}.json"), rec))
    return out


def test_the_same_store_gives_byte_identical_files(tmp_path):
    cells = _swept_cells()
    pages = []
    for k in range(2):
        page_path = tmp_path / f"gen{k}" / "claims.md"
        page = build_page(cells, [], [], "claims")
        assert page.figures, "a latent-d sweep draws its dose-response figure"
        write_page(page, page_path)
        pages.append({p.relative_to(page_path.parent): p.read_bytes() for p in page_path.parent.rglob("*")
                      if p.is_file()})
    assert pages[0] == pages[1]
    pngs = [data for name, data in pages[0].items() if name.suffix == ".png"]
    assert pngs and all(b"tEXt" not in png and b"tIME" not in png for png in pngs)
    text = pages[0][Path("claims.md")].decode()
    assert "4 of 0 cells" in text and "(claims/dose_latent_dim" in text and json.dumps(str(tmp_path))[1:-1] not in text


def test_grids_with_later_seeds_are_marked_with_why():
    from gsbench.grids.grid_file import parse_grid
    base = {"study": "custom", "base": {"method": "gaussiands", "preset": "cpu-small"}, "scenes": ["tabletop-small"],
            "axes": {"semantic.latent_dim": [3, 6]}}
    later = parse_grid({**base, "seeds": [0, 1, 2, 3, 5], "later_seeds": {"seeds": [2, 3, 5], "why": "it read blind"}},
                       path=Path("later.yaml"))
    planned = parse_grid({**base, "seeds": [0, 1, 2]}, path=Path("planned.yaml"))
    text = build_page([], [], [later, planned], "claims").text
    assert "| later | custom | 5 \\* | 0 | 10 |" in text and "| planned | custom | 3 | 0 | 6 |" in text
    assert "- later, seeds 2–3, 5: it read blind." in text and "- planned" not in text
    assert "two looks at the data" in text


def test_the_page_opens_with_the_claim_by_regime_matrix(committed_page):
    from gsbench.methods.gaussiands.study_table import PAPER_CLAIMS, REGIMES
    lines = committed_page.text.splitlines()
    sections = [ln for ln in lines if ln.startswith("## ")]
    assert sections[0] == "## Claims by regime"
    header = "| Claim | " + " | ".join(d.name for d in REGIMES) + " |"
    at = lines.index(header)
    assert lines.index(sections[1]) > at            # before the status and the detailed tables
    rows = lines[at + 2:at + 2 + len(PAPER_CLAIMS)]
    assert len(rows) == len(PAPER_CLAIMS) and all(r.startswith("| ") for r in rows)
    cells = [[c.strip() for c in r.strip("|").split("|")] for r in rows]
    words = ("reproduced", "opposite", "inconclusive", "not run", "not testable", "smaller than claimed",
             "larger than claimed", "not reproduced", "blind", "not measured")
    assert all(x.startswith(words) for c in cells for x in c[1:])
    by_text = {c.text: c for c in PAPER_CLAIMS}
    # the headline rows ran in every declared regime
    assert all("not run" not in c[1:] for c in cells if by_text[c[0].rstrip(" †")].study == "reconstruction")
    # no control ran in the dense regime (true until one is added there): a dense cell that is guarded by
    # a control and not blind excludes zero (a rejecting verdict), or its metric was not measured
    assert all(c[1].startswith(("blind: no control in this regime", "larger than claimed", "smaller than claimed",
                                "opposite", "reproduced", "not reproduced", "not measured"))
               for c in cells if not by_text[c[0].rstrip(" †")].unguarded)
    for d in REGIMES:
        assert d.name in committed_page.readme_block
