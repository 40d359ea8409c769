"""Write the whole report: collected table, Markdown + LaTeX tables, PNG plots, index.html.

Inputs are the collected long table (gsbench.collect), the train_log.jsonl of the runs it lists
(time curves, loss shares), and their results.json for the training budget when the collected
table does not carry it.

The report folder is written whole (gsbench.outdir): into a staging folder beside it, swapped in
when complete, with a manifest of its files; a folder holding files the report did not write is
refused (or, with force, they are kept), and of the old report only its own files are deleted.
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import pandas as pd

from gsbench.collect import collect, read_collected, write_collected
from gsbench.errors import InputError
from gsbench.outdir import OwnedFolder
from gsbench.reports import doseplots, plots, shares
from gsbench.reports import html as html_mod
from gsbench.reports import pictures as pictures_mod

from gsbench.reports.ablations import (depth_formulation_table, latent_diff_table, loss_subsets_table,  # isort: skip
                                       method_diff_table, noise_table, ordering_table, other_study_tables)
from gsbench.methods.gaussiands.study_table import MAIN_STUDIES
from gsbench.reports.budgets import budget_table
from gsbench.reports.claims_table import claims_table
from gsbench.reports.controls import controls_table
from gsbench.reports.data import Results, is_null
from gsbench.reports.display import STUDIES
from gsbench.reports.studies import reconstruction_table, removal_table, semantic_table
from gsbench.reports.sweeps import lambda_table, latent_dim_tables
from gsbench.reports.table import Table
from gsbench.store import write_text_atomic

# table id prefix -> section (study) it belongs to
_SECTION_OF = [
    ("reconstruction", "main"), ("lerf_", "main"), ("3dovs_", "main"), ("removal", "main"),
    ("ordering", "ordering"), ("depth_formulation", "depth_formulation"), ("loss_subsets", "loss_subsets"),
    ("latent_dim", "latent_dim"), ("lambda_", "lambda_grid"), ("depth_noise", "depth_noise"),
]
# the studies' sections in report order: the paper's layout (_SECTION_OF), then any other paper study as declared
_STUDY_ORDER = list(dict.fromkeys([sec for _, sec in _SECTION_OF if sec != "main"]
                                  + [k for k in STUDIES if k != "reconstruction"]))
_SECTION_TITLES = {
    "main": "Main results (reconstruction and segmentation)",
    **{k: v for k, v in STUDIES.items() if k != "reconstruction"},
    "claims": "Paper claims: reproduced or not",
    "budgets": "Training budget per method",
    "pictures": "Pictures: renders, depth and masks per scene and method",
}
_NO_BARS = ("latent_dim", "lambda_pearson", "paper_claims", "claims_controls", "budgets")


@dataclass
class ReportSummary:
    out_dir: Path
    index: Path
    tables: list[str] = field(default_factory=list)
    plots: list[Path] = field(default_factory=list)
    pictures: list[Path] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    collected: Path | None = None
    unreadable: int = 0          # results.json files that could not be read (each a failed run row)

    def rebased(self, old: Path, new: Path) -> "ReportSummary":
        """The same summary with the paths under `old` (the staging folder) moved to `new`."""
        def move(p: Path) -> Path:
            return new / p.relative_to(old)
        return dataclasses.replace(self, out_dir=new, index=move(self.index), plots=[move(p) for p in self.plots],
                                   pictures=[move(p) for p in self.pictures],
                                   collected=move(self.collected) if self.collected else None)


def _writer_version() -> str:
    try:
        from importlib.metadata import version
        return version("gsbench")
    except Exception:  # not installed as a distribution
        return "unknown"


def load_results(source: str | Path) -> tuple[pd.DataFrame, str]:
    """A runs folder is collected now; a collected.parquet / .csv file is read as is."""
    source = Path(source)
    if source.is_file():
        return read_collected(source), str(source)
    if not source.exists():
        raise FileNotFoundError(f"{source}: runs folder not found")
    return collect(source), str(source)


def _section_of(table_id: str) -> str:
    for prefix, sec in _SECTION_OF:
        if table_id.startswith(prefix):
            return sec
    return "main"


def build_report(source: str | Path, out_dir: str | Path, progress: bool = False,
                 force: bool = False) -> ReportSummary:
    """Build the report for a runs folder (or a collected table) into out_dir, whole (module docstring).
    `force`: write into a folder that holds files the report did not write, keeping them."""
    with OwnedFolder(out_dir, "gsbench report", force=force, what="report folder") as folder:
        assert folder.staging is not None
        staging = folder.staging
        summary = _write_report(source, staging, progress)
        folder.commit()
    return summary.rebased(staging, folder.out)


def _write_report(source: str | Path, out_dir: Path, progress: bool) -> ReportSummary:
    """Every file of the report, into the empty folder out_dir."""
    df, src = load_results(source)
    if df.empty:
        raise InputError(f"{source}: no results to report")
    plot_dir = out_dir / "plots"
    table_dir = out_dir / "tables"
    plot_dir.mkdir()
    table_dir.mkdir()
    summary = ReportSummary(out_dir=out_dir, index=out_dir / "index.html")
    summary.unreadable = len(df.attrs.get("unreadable", []))
    if summary.unreadable:
        summary.notes.append(f"Could not read {summary.unreadable} results.json file(s); each run is reported as "
                             "failed with the reason, the other runs as usual.")
    summary.notes += list(df.attrs.get("warnings", []))
    summary.collected = write_collected(df, out_dir)

    res = Results(df)
    tables = build_tables(res)
    summary.tables = [t.id for t in tables]
    _write_tables(tables, table_dir, out_dir)

    sections: dict[str, html_mod.Section] = {}

    def section(key: str) -> html_mod.Section:
        if key not in sections:
            sections[key] = html_mod.Section(key, _SECTION_TITLES.get(key, key))
        return sections[key]

    steps = list(tables)
    it: Any = steps
    if progress:
        from tqdm import tqdm
        it = tqdm(steps, desc="report tables/plots", unit="table")
    for t in it:
        sec = section(t.section or _section_of(t.id))
        sec.tables.append(t)
        if not t.id.startswith(_NO_BARS) and not t.id.endswith("_diff"):
            p = plots.plot_table_bars(t, plot_dir / f"bars_{t.id}.png")
            if p:
                summary.plots.append(p)
                sec.figures.append(
                    (p.relative_to(out_dir).as_posix(), f"{t.title}: bars per row; error bars = std over seeds.")
                )

    studies = res.studies()
    main_ids = res.run_ids(study=MAIN_STUDIES)
    _study_figures(res, studies, main_ids, plot_dir, out_dir, section, summary)
    _extra_figures(res, plot_dir, out_dir, section, summary)
    summary.notes += _absence_notes(res, tables, studies, main_ids)

    block, pictures = pictures_mod.pictures_html(res, out_dir, summary.notes)
    if block:
        section("pictures").blocks.append(block)
        summary.pictures = pictures
    order = ["main", "pictures", "budgets", "claims"] + _STUDY_ORDER
    ordered = [sections[k] for k in order if k in sections] + [s for k, s in sections.items() if k not in order]
    links = [("tables.md", "tables (Markdown)"), ("tables.tex", "tables (LaTeX)"),
             (summary.collected.name, f"collected results ({summary.collected.suffix[1:]})")]
    generated = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    html_mod.write_index(summary.index, "gsbench report", src, generated, ordered, summary.notes, res, links,
                         _writer_version())
    return summary


def _study_figures(res: Results, studies: Any, main_ids: list[str], plot_dir: Path, out_dir: Path,
                   section: Callable[[str], html_mod.Section], summary: ReportSummary) -> None:
    """Error against run time and loss shares, one figure each per study (the main runs as one)."""
    groups: list[tuple[str, Any, list[str]]] = []
    if main_ids:
        groups.append(("main", None, main_ids))
    for st in sorted(s for s in studies if s not in MAIN_STUDIES):
        groups.append((st if st in STUDIES else f"other_{st}", st, res.run_ids(study=st)))
    for key, st, ids in groups:
        p, notes = plots.plot_time_curves(res, st if key != "main" else None, ids, plot_dir / f"time_{_slug(key)}.png")
        sec = section(key)
        if key.startswith("other_"):
            sec.title = f"Study '{st}' (no paper layout)"
        sec.notes += notes
        if p:
            summary.plots.append(p)
            sec.figures.append(
                (
                    p.relative_to(out_dir).as_posix(),
                    "Error against run time: lines = PSNR / mIoU of the periodic evaluations in train_log.jsonl over "
                    "the optimiser's wall clock; dots = final results vs total training time (train_s, which "
                    "also counts priors and set-up, so dots can sit right of the lines' ends); dashed = Pareto "
                    "front of final value vs total time (one per scene).",
                )
            )
        else:
            sec.notes.append(
                "No time curve: the runs have neither periodic evaluations nor final values with a training time."
            )
        p, notes = shares.plot_loss_shares(
            res, st if key != "main" else None, ids, plot_dir / f"shares_{_slug(key)}.png"
        )
        sec.notes += notes
        if p:
            summary.plots.append(p)
            sec.figures.append((p.relative_to(out_dir).as_posix(),
                                "Loss shares: each weighted loss term's share of the total loss over training steps "
                                "(train_log.jsonl loss_share), one panel per configuration, mean over its seeds (n)."))


def _extra_figures(res: Results, plot_dir: Path, out_dir: Path, section: Callable[[str], html_mod.Section],
                   summary: ReportSummary) -> None:
    """The study-specific figures: lambda surfaces, noise, latent d, dose response."""
    for p in plots.plot_lambda_surfaces(res, plot_dir / "lambda_surfaces"):
        summary.plots.append(p)
        section("lambda_grid").figures.append(
            (
                p.relative_to(out_dir).as_posix(),
                "Lambda response surfaces: mean mIoU per pair of lambdas (others averaged), "
                "Pearson r of each lambda with mIoU in the axis labels.",
            )
        )
    for p in plots.plot_noise(res, plot_dir / "noise"):
        summary.plots.append(p)
        section("depth_noise").figures.append(
            (
                p.relative_to(out_dir).as_posix(),
                "Metric vs depth-noise severity per perturbation kind (severity 0 = clean run).",
            )
        )
    for p in plots.plot_latent(res, plot_dir / "latent_dim"):
        summary.plots.append(p)
        section("latent_dim").figures.append((p.relative_to(out_dir).as_posix(),
                                              "Latent-d trade-off: accuracy against cost; dashed = reference method."))

    for p in doseplots.plot_doses(res, plot_dir / "dose"):
        summary.plots.append(p)
        section("claims").figures.append(
            (p.relative_to(out_dir).as_posix(),
             "Dose response: mean over seeds and its 95 % band against the swept value; dashed line / crosses = "
             "the paper's setting or its reported values."))


def _absence_notes(res: Results, tables: list[Table], studies: Any, main_ids: list[str]) -> list[str]:
    """What is absent and why, each table's notes, and the long n/a reasons in full."""
    notes: list[str] = []
    absent = []
    if not main_ids:
        absent.append("main results (standalone / reconstruction runs)")
    for st in _STUDY_ORDER:
        if st not in studies:
            absent.append(st)
    if absent:
        notes.append("No runs for: " + ", ".join(absent) + " (their tables and plots are left out).")
    if main_ids and not any(t.id.startswith(("reconstruction", "lerf_", "3dovs_")) for t in tables):
        notes.append("Main runs exist but carry none of the reconstruction / segmentation metrics.")
    unknown = sorted(s for s in studies if s not in MAIN_STUDIES and s not in STUDIES)
    if unknown:
        notes.append("Studies without a paper layout (generic table by grid axis): "
                     + ", ".join(map(str, unknown)) + ".")
    for t in tables:
        notes += [f"{t.title}: {n}" for n in t.notes]
    for short, full in sorted(res.long_reasons.items()):
        for f in sorted(full)[:5]:
            notes.append(f"n/a ({short}) in full: {f}")
    return notes


def build_tables(res: Results) -> list[Table]:
    """Every table that has data, in the paper's order."""
    tables: list[Table] = []
    tables += reconstruction_table(res)
    tables += semantic_table(res, "lerf", ["miou_lerf"], "lerf_miou", "LERF-OVS mIoU per scene",
                             "Open-vocabulary segmentation on LERF-OVS scenes (mIoU, %; LangSplat protocol).")
    tables += semantic_table(res, "lerf", ["loc_acc_lerf"], "lerf_loc_acc", "LERF-OVS localization accuracy",
                             "Localization accuracy on LERF-OVS scenes (%).")
    tables += semantic_table(res, "3dovs", ["miou_3dovs", "mbiou_3dovs"], "3dovs_miou_mbiou",
                             "3D-OVS mIoU and mBIoU per scene",
                             "Boundary-aware semantic segmentation on 3D-OVS scenes (mIoU and boundary mIoU, %).")
    tables += removal_table(res)
    tables += method_diff_table(res)
    tables += ordering_table(res)
    tables += depth_formulation_table(res)
    tables += loss_subsets_table(res)
    tables += latent_dim_tables(res)
    tables += latent_diff_table(res)
    tables += lambda_table(res)
    tables += noise_table(res)
    tables += other_study_tables(res)
    tables += claims_table(res)
    tables += controls_table(res)
    tables += budget_table(res)
    return tables


def _write_tables(tables: list[Table], table_dir: Path, out_dir: Path) -> None:
    md, tex = ["# gsbench tables", ""], [
        "% gsbench tables. Needs \\usepackage{booktabs,graphicx,amssymb} (amssymb for \\checkmark).", ""]
    for t in tables:
        m, x = t.to_markdown(), t.to_latex()
        write_text_atomic(table_dir / f"{t.id}.md", m)
        write_text_atomic(table_dir / f"{t.id}.tex", x)
        md += [m, ""]
        tex += [x, ""]
    if not tables:
        md.append("No table has data.")
    write_text_atomic(out_dir / "tables.md", "\n".join(md))
    write_text_atomic(out_dir / "tables.tex", "\n".join(tex))


def _slug(s: Any) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in str(s)) if not is_null(s) else "none"
