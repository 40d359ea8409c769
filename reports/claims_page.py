"""docs/claims.md from the published results store: the paper-claims table, the positive controls,
the dose-response figures and a verdict count, which commits / machines produced the cells, and the
stale cells; plus the short block the README carries between its claims markers.

Why generated and checked: the table is the benchmark's product, so no number in it may be typed
by hand. The page is a function of the store alone (no date, no path, PNGs without their text
metadata), so the same store gives byte-identical files and CI can regenerate it and compare
(`check_page` returns the differing lines).
"""
from __future__ import annotations

import difflib
import struct
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

from gsbench.collect import collect
from gsbench.errors import InputError
from gsbench.grids.grid_file import Grid
from gsbench.grids.store import Published, Stale
from gsbench.methods.gaussiands.paper import PAPER_CLAIMS
from gsbench.numerics import NUMERICS_VERSION
from gsbench.reports import doseplots
from gsbench.reports.claims_spread import spread_table
from gsbench.reports.claims_table import CLAIM_COLUMNS, NOT_RUN, claims_table, not_run_row
from gsbench.reports.controls import CONTROLS, control_status, controls_table
from gsbench.reports.data import Results
from gsbench.reports.display import metric_spec
from gsbench.reports.table import Cell, Column, Row, Table
from gsbench.store import write_bytes_atomic, write_json_atomic, write_text_atomic

README_BEGIN = "<!-- claims:begin -->"
README_END = "<!-- claims:end -->"
COMMAND = "gsbench publish --page docs/claims.md --from results/cpu --readme README.md"
FIGURE_PREFIX = "dose"
# PNG chunks that carry text or a time (matplotlib writes its version as "Software"): left out
_TEXT_CHUNKS = (b"tEXt", b"zTXt", b"iTXt", b"tIME")


@dataclass
class Page:
    text: str
    readme_block: str
    figures: dict[str, bytes] = field(default_factory=dict)   # file name -> PNG bytes


def strip_png_text(data: bytes) -> bytes:
    """The PNG without its text and time chunks (the pixels are untouched), so it is a function of
    the plot alone."""
    sig = b"\x89PNG\r\n\x1a\n"
    if not data.startswith(sig):
        raise ValueError("not a PNG")
    out, i = [sig], len(sig)
    while i + 8 <= len(data):
        (length,) = struct.unpack(">I", data[i:i + 4])
        kind = data[i + 4:i + 8]
        end = i + 12 + length
        if kind not in _TEXT_CHUNKS:
            out.append(data[i:end])
        i = end
    return b"".join(out)


# ----------------------------------------------------------------------------- tables with no cell
def empty_claims_table() -> Table:
    """The claims table before any claim study has a published cell: every row 'not run'."""
    rows = [not_run_row(c) for c in PAPER_CLAIMS]
    return Table("paper_claims", "Paper claims", "No cell of a claim study is published: every claim is 'not run'.",
                 ["Claim", "Paper source", "Scene"], CLAIM_COLUMNS, rows)


def empty_controls_table() -> Table:
    """The controls table before any control has a published cell."""
    rows = [Row([c.text, f"{c.study} ({metric_spec(c.metric).label})", "–", "–"],
                [Cell(text="study not run"), Cell(text=NOT_RUN)]) for c in CONTROLS]
    cols = [Column("measured", "Effect [95 % CI] (n); MDE; Holm p", "Effect [95\\% CI] (n); MDE; Holm p"),
            Column("mark", "Control", "Control")]
    return Table("claims_controls", "Positive controls", "No cell of a control is published: every control is "
                 "'not run'.", ["Control", "Study (metric)", "Scene", "Row"], cols, rows)


def _column_at(table: Table, key: str) -> int:
    """The index of the table's column `key` among a row's cells."""
    return [c.metric for c in table.columns].index(key)


def verdict_counts(table: Table) -> dict[str, int]:
    """Rows per verdict (its words before any ':' detail), in first-seen order."""
    out: dict[str, int] = {}
    at = _column_at(table, "verdict")
    for r in table.rows:
        v = (r.cells[at].text or "").split(":", 1)[0].strip()
        out[v] = out.get(v, 0) + 1
    return out


def seed_rule_line(table: Table) -> str:
    """How many claim rows meet the seed rule (the 'Seeds for the MDE' column), and how many need more."""
    at = _column_at(table, "seeds")
    texts = [r.cells[at].text or "" for r in table.rows]
    met = sum(t.endswith("(met)") for t in texts)
    short = sum(t.endswith("more)") or t.startswith(">") for t in texts)
    return (f"Seed rule (an MDE of at most half the paper's effect; robustness: at most the margin): met by {met} "
            f"rows, {short} need more seeds, {len(texts) - met - short} have no target or no interval yet.")


# ----------------------------------------------------------------------------- the page
def machines(cells: Iterable[Published]) -> list[tuple[str, int]]:
    """(commit / numerics version / CPU line, number of cells) of the cells, most cells first."""
    counts: dict[str, int] = {}
    for c in cells:
        p = c.record["provenance"]
        dirty = " with uncommitted changes" if p.get("gsbench_commit_dirty") is True else ""
        line = (f"commit {str(p.get('gsbench_commit') or 'unknown')[:12]}{dirty}, "
                f"numerics version {c.numerics_version}, "
                f"{p.get('cpu_model') or 'unknown CPU'} ({p.get('physical_cores') or '?'} cores, "
                f"{p.get('torch_threads') or '?'} threads), torch {p.get('torch')}, numba {p.get('numba')}, "
                f"numpy {p.get('numpy')}, threading layer {p.get('numba_threading_layer')}")
        counts[line] = counts.get(line, 0) + 1
    return sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))


def _results(current: list[Published], work: Path) -> Results | None:
    """The collected table of the current cells (their results.json materialised under work)."""
    if not current:
        return None
    for c in current:
        write_json_atomic(work / "runs" / c.run_id / "results.json", {**c.record["results"],
                                                                        "config": c.record["config"]})
    return Results(collect(work / "runs"))


def _figures(res: Results | None, work: Path) -> dict[str, bytes]:
    if res is None:
        return {}
    out = {}
    for p in doseplots.plot_doses(res, work / "img" / FIGURE_PREFIX):
        out[p.name] = strip_png_text(p.read_bytes())
    return dict(sorted(out.items()))


def _seed_span(seeds: list[int]) -> str:
    """[3, 4, 5, 9] -> '3–5, 9'."""
    runs: list[list[int]] = []
    for s in sorted(seeds):
        if runs and s == runs[-1][-1] + 1:
            runs[-1].append(s)
        else:
            runs.append([s])
    return ", ".join(f"{r[0]}–{r[-1]}" if len(r) > 1 else str(r[0]) for r in runs)


def _grid_lines(current: list[Published], grids: list[Grid]) -> list[str]:
    """The per-grid status table, then the grids whose seeds were extended after a look at their results."""
    lines = ["| Grid | Study | Seeds | Published cells | Cells of the plan |", "|:--|:--|--:|--:|--:|"]
    for g in grids:
        seeds = f"{len(g.seeds)}" + (" \\*" if g.later_seeds else "")
        lines.append(f"| {g.name} | {g.study} | {seeds} | {sum(c.grid == g.name for c in current)} | "
                     f"{len(g.cells())} |")
    later = [g for g in grids if g.later_seeds]
    if later:
        lines += ["", "\\* Seeds added after a first look at the grid's results, so its verdicts had two looks at "
                      "the data (docs/grids.md, \"Seeds\"):", ""]
        lines += [f"- {g.name}, seed{'s' if len(g.later_seeds) > 1 else ''} {_seed_span(g.later_seeds)}: "
                  f"{g.later_why}." for g in later]
    return lines


def build_page(current: list[Published], stale: list[Stale], grids: list[Grid], figure_dir: str) -> Page:
    """The page text, the README block and the figures (name -> bytes) for the store's cells;
    `figure_dir` is the figures' folder relative to the page."""
    with tempfile.TemporaryDirectory(prefix="gsbench-claims-page-") as tmp:
        res = _results(current, Path(tmp))
        claims = (claims_table(res) if res is not None else []) or [empty_claims_table()]
        controls = (controls_table(res) if res is not None else []) or [empty_controls_table()]
        spread = spread_table(res) if res is not None else []
        figures = _figures(res, Path(tmp))
    planned = sum(len(g.cells()) for g in grids)
    counts = verdict_counts(claims[0])
    marks = ({c.key: control_status(res, c) for c in CONTROLS} if res is not None
             else {c.key: NOT_RUN for c in CONTROLS})
    mark_counts: dict[str, int] = {}
    for m in marks.values():
        mark_counts[m] = mark_counts.get(m, 0) + 1
    verdicts = ", ".join(f"{v} {n}" for v, n in counts.items())
    controls_line = ", ".join(f"{m} {n}" for m, n in mark_counts.items())
    lines = ["# Paper claims on CPU: the published table", "",
             f"<!-- generated by `{COMMAND}` from the store; do not edit: CI regenerates it and fails on a "
             "difference -->", "",
             "The numbers below come from the published results store `results/cpu/` (one JSON file per finished "
             "cell of the claims plan, with its config and provenance; docs/publishing.md). Each one can be "
             "re-run with `gsbench verify results/cpu --cells K`.", "",
             "## Status", "",
             f"{len(current)} of {planned} cells of the claims plan are published and current "
             f"(numerics version {NUMERICS_VERSION}); {len(stale)} stale."]
    if not current:
        lines += ["", "**No cell is published yet**: every row below is \"not run\". The full run is "
                      "`gsbench claims --out RUNS`, then `gsbench publish RUNS --to results/cpu` (docs/publishing.md)."]
    lines += ["", *_grid_lines(current, grids), "",
              "## Verdicts", "", f"Claims ({len(claims[0].rows)} rows): {verdicts}.", "",
              seed_rule_line(claims[0]), "",
              f"Positive controls ({len(CONTROLS)}): {controls_line}.", ""]
    lines += [claims[0].to_markdown(), *[t.to_markdown() for t in spread], controls[0].to_markdown(),
              "## Dose response", ""]
    if figures:
        lines += [f"![{name}]({figure_dir}/{name})\n" for name in figures]
    else:
        lines += ["No figure: no published cell of a swept study.", ""]
    lines += ["## Produced by", ""]
    who = machines(current)
    lines += [f"- {n} cells: {line}" for line, n in who] if who else ["No cell yet."]
    lines += ["", "## Stale cells", "",
              "Published cells whose run id or numerics version today's plan and code no longer give; they are "
              "kept in the store, never reused by `gsbench claims` and never in the tables above.", ""]
    lines += [f"- `{s.cell.grid}/{s.cell.run_id}`: {s.reason}" for s in stale] if stale else ["None."]
    block = (f"{README_BEGIN}\n**Paper claims on CPU** ([docs/claims.md](docs/claims.md), generated from "
             f"`results/cpu/`): {len(current)} of {planned} cells published; claims: {verdicts}; "
             f"positive controls: {controls_line}.\n{README_END}")
    return Page("\n".join(lines).rstrip() + "\n", block, figures)


# ----------------------------------------------------------------------------- writing and checking
def figure_folder(page_path: Path) -> Path:
    """docs/claims.md -> docs/claims/ (the page's figures)."""
    return page_path.with_suffix("")


def readme_with_block(readme: str, block: str, where: str) -> str:
    """The README text with the block between its markers replaced."""
    start, end = readme.find(README_BEGIN), readme.find(README_END)
    if start < 0 or end < start:
        raise InputError(f"{where}: no {README_BEGIN} ... {README_END} block to regenerate")
    return readme[:start] + block + readme[end + len(README_END):]


def write_page(page: Page, page_path: Path, readme_path: Path | None = None) -> list[Path]:
    """Write the page, its figures (old figures of the page removed) and the README block."""
    page_path = Path(page_path)
    written = [page_path]
    write_text_atomic(page_path, page.text)
    folder = figure_folder(page_path)
    for old in sorted(folder.glob(f"{FIGURE_PREFIX}_*.png")) if folder.is_dir() else []:
        if old.name not in page.figures:
            old.unlink()
    for name, data in page.figures.items():
        write_bytes_atomic(folder / name, data)
        written.append(folder / name)
    if readme_path is not None:
        readme_path = Path(readme_path)
        write_text_atomic(readme_path, readme_with_block(readme_path.read_text(encoding="utf-8"), page.readme_block,
                                                         str(readme_path)))
        written.append(readme_path)
    return written


def check_page(page: Page, page_text: str, readme_text: str | None = None,
               figure_names: list[str] | None = None) -> list[str]:
    """The lines that differ between the regenerated page (and README block, figure names) and the
    committed ones; [] when they agree. Figures are compared by name: their pixels depend on the
    matplotlib and FreeType versions, the numbers they show are in the page's tables."""
    diff = [ln for ln in difflib.unified_diff(page_text.splitlines(), page.text.splitlines(), "committed",
                                              "regenerated", lineterm="", n=0)
            if ln.startswith(("+", "-")) and not ln.startswith(("+++", "---"))]
    if readme_text is not None:
        start, end = readme_text.find(README_BEGIN), readme_text.find(README_END)
        committed = readme_text[start:end + len(README_END)] if 0 <= start < end else "(no claims block)"
        if committed != page.readme_block:
            diff += [f"- README: {committed}", f"+ README: {page.readme_block}"]
    if figure_names is not None and sorted(figure_names) != sorted(page.figures):
        diff += [f"- figures: {', '.join(sorted(figure_names))}", f"+ figures: {', '.join(sorted(page.figures))}"]
    return diff
