"""Build the paper's main tables (I-III, removal) from the collected results, and the helpers that
every table builder shares (the ablations live in ablations.py, latent d and lambdas in sweeps.py).

Cell = all runs of one configuration (method, scene, protocol, grid-axis values) that differ only by
seed: mean +- sample std over seeds. Runs evaluated under different protocols are never averaged
(protocol is part of every cell, and tables are sectioned or grouped by protocol). A cell whose runs
differ by more than seed (config hash or providers) is still averaged but named in a table note.
Builders return [] when the study has no runs, so a report shows only the tables that have data.
"""
from __future__ import annotations

from typing import Any

from gsbench.methods.gaussiands.study_table import MAIN_STUDIES
from gsbench.reports.data import Results, is_null, mean_of_cells, same

from gsbench.reports.display import (AX_FORMULATION, AX_NOISE_TYPE, AX_ORDERING, FORMULATION_LABELS,  # isort: skip
                                  FORMULATION_ORDER, NOISE_LABELS, NOISE_ORDER, ORDERING_LABELS, ORDERING_ORDER,
                                  PROTOCOL_LABELS, MetricSpec, method_label, metric_spec)
from gsbench.method_table import method_sort_key
from gsbench.reports.table import Cell, Column, Row, Table, _tex

PROTOCOL_ORDER = ["3dovs", "lerf", None]
PROTOCOL_SHORT = {"3dovs": "3D-OVS", "lerf": "LERF-OVS", None: "no protocol"}


# ---------------------------------------------------------------------------- helpers
def _protocol_rank(p: Any) -> int:
    p = None if is_null(p) else p
    return PROTOCOL_ORDER.index(p) if p in PROTOCOL_ORDER else len(PROTOCOL_ORDER)


def ordered_methods(methods: list) -> list:
    return sorted(methods, key=method_sort_key)


def scene_protocols(res: Results, ids: list[str]) -> list[tuple[str, Any]]:
    """Distinct (scene, protocol) pairs, protocol-major (3D-OVS, LERF, none), then scene name."""
    pairs: list[tuple[str, Any]] = []
    for rid in ids:
        sc, pr = res.runs.at[rid, "scene"], res.runs.at[rid, "protocol"]
        pr = None if is_null(pr) else pr
        if (sc, pr) not in pairs:
            pairs.append((sc, pr))
    return sorted(pairs, key=lambda t: (_protocol_rank(t[1]), str(t[0])))


def runs_of(res: Results, ids: list[str], scene: str, protocol: Any, done_only: bool = False) -> list[str]:
    """The runs among `ids` of one (scene, protocol) pair (optionally only finished ones)."""
    return [r for r in ids if res.runs.at[r, "scene"] == scene and same(res.runs.at[r, "protocol"], protocol)
            and (not done_only or res.runs.at[r, "status"] == "done")]


def _spec_for(metric: str) -> MetricSpec:
    return metric_spec(metric)


def _seed_note(cells: list[Cell]) -> str:
    ns = [c.total for c in cells if c.total > 0 and c.check is None and c.text is None]
    if not ns:
        return ""
    lo, hi = min(ns), max(ns)
    seeds = f"{lo}" if lo == hi else f"{lo}-{hi}"
    if hi > 1:
        return f" Runs per cell: {seeds}; cells with several seeds show mean ± sample std (ddof=1)."
    return " One run (seed) per cell."


def _finish(t: Table, mixed: list[str]) -> Table:
    t.caption += _seed_note([c for r in t.rows for c in r.cells])
    if mixed:
        t.notes.append("Cells whose runs differ by more than the seed (different config or providers), "
                       "averaged anyway: " + ", ".join(mixed[:10]) + (" ..." if len(mixed) > 10 else ""))
    return t


def _cell(res: Results, rids: list[str], metric: str | None, mixed: list[str], where: str,
          spec: MetricSpec | None = None) -> Cell:
    if res.mixed_configs(rids) and where not in mixed:
        mixed.append(where)
    return res.cell(rids, metric, spec)


def _axis_label(col: str, v: Any) -> str:
    if is_null(v):
        return "–"
    if col == AX_ORDERING:
        return ORDERING_LABELS.get(v, str(v))
    if col == AX_FORMULATION:
        return FORMULATION_LABELS.get(v, str(v))
    if col == AX_NOISE_TYPE:
        return NOISE_LABELS.get(v, str(v))
    if isinstance(v, float):
        # 3.0 -> "3", 1e38 -> "1e+38" (never a 39-digit integer)
        return str(int(v)) if v.is_integer() and abs(v) < 1e15 else f"{v:g}"
    return str(v)


def _axis_rank(col: str, v: Any) -> tuple:
    if is_null(v):
        return (0, 0, "")
    for c, order in ((AX_ORDERING, ORDERING_ORDER), (AX_FORMULATION, FORMULATION_ORDER), (AX_NOISE_TYPE, NOISE_ORDER)):
        if col == c:
            return (1, order.index(v) if v in order else len(order), str(v))
    if isinstance(v, bool):
        return (1, int(v), "")
    if isinstance(v, (int, float)):
        return (1, float(v), "")
    return (1, 0, str(v))


# ---------------------------------------------------------------------------- Table I
def reconstruction_table(res: Results) -> list[Table]:
    """Per scene (sectioned by protocol) x method: SSIM, PSNR, LPIPS, FPS; best across methods bold."""
    ids = res.run_ids(study=MAIN_STUDIES)
    metrics = ["ssim", "psnr", "lpips", "fps"]
    if not ids or not any(res.has_metric(ids, m) for m in metrics):
        return []
    methods = ordered_methods(res.distinct("method", ids))
    columns = []
    for meth in methods:
        for m in metrics:
            sp = _spec_for(m)
            columns.append(Column(m, sp.label, sp.latex, sp.better, group=method_label(meth),
                                  group_latex=f"\\textbf{{{_tex(method_label(meth))}}}"))
    rows, mixed = [], []
    for scene, protocol in scene_protocols(res, ids):
        cells = []
        for meth in methods:
            rids = res.run_ids(study=MAIN_STUDIES, method=meth, scene=scene, protocol=protocol)
            for m in metrics:
                cells.append(_cell(res, rids, m, mixed, f"{scene}/{meth}"))
        rows.append(Row([scene], cells, section=PROTOCOL_LABELS.get(protocol, str(protocol))))
    t = Table("reconstruction", "Reconstruction per scene and method",
              "Reconstruction results per scene: SSIM, PSNR, LPIPS and FPS of each method "
              "(best value per scene and metric in bold; FPS is machine-dependent).",
              ["Scene"], columns, rows)
    t.bold_best_per_row()
    return [_finish(t, mixed)]


# ---------------------------------------------------------------------------- Tables II / III
def semantic_table(res: Results, protocol: str, base_metrics: list[str], table_id: str, title: str,
                   caption: str) -> list[Table]:
    """Methods as rows, scenes (x metrics) as columns plus Overall; best per column bold.
    Encode / decode query modes get their own rows when the results carry them."""
    # A run belongs here when it carries the protocol's metrics (a synthetic scene is evaluated under
    # both protocols; the metric names, e.g. miou_lerf vs miou_3dovs, keep protocols apart).
    ids = [r for r in res.run_ids(study=MAIN_STUDIES) if any(res.has_metric([r], m) for m in base_metrics)]
    if not ids:
        return []
    scenes = sorted({res.runs.at[r, "scene"] for r in ids}, key=str)
    single = len(base_metrics) == 1
    columns: list[Column] = []
    for sc in scenes + ["Overall"]:
        for m in base_metrics:
            sp = _spec_for(m)
            if single:
                columns.append(Column(m, sc, _tex(sc), sp.better))
            else:
                short = sp.label.replace(" (%)", "")
                columns.append(Column(m, short, sp.latex.replace(" (\\%)", ""), sp.better, group=sc))
    rows, mixed = [], []
    for meth in ordered_methods(res.distinct("method", ids)):
        mids = [r for r in ids if res.runs.at[r, "method"] == meth]
        has_modes = all(any(res.has_metric(mids, m + sfx) for m in base_metrics) for sfx in ("_encode", "_decode"))
        for suffix, label in (("", ""), ("_encode", " (encode)"), ("_decode", " (decode)")):
            names = [m + suffix for m in base_metrics]
            if not any(res.has_metric(mids, n) for n in names):
                continue
            if suffix == "" and has_modes:  # the configured mode repeats one of the two mode rows
                continue
            per_scene: dict[str, list[Cell]] = {n: [] for n in names}
            cells: list[Cell] = []
            for sc in scenes:
                rids = [r for r in mids if res.runs.at[r, "scene"] == sc]
                for n, base in zip(names, base_metrics):
                    c = _cell(res, rids, n, mixed, f"{sc}/{meth}", _spec_for(base))
                    per_scene[n].append(c)
                    cells.append(c)
            for n, base in zip(names, base_metrics):
                cells.append(mean_of_cells(per_scene[n], scenes, _spec_for(base).decimals))
            rows.append(Row([method_label(meth) + label], cells))
    if not rows:
        return []
    if any(r.labels[0].endswith(("(encode)", "(decode)")) for r in rows):
        caption += (" (encode) = the paper's query mode (text -> CLIP -> AE encoder, cosine with the rendered "
                    "latent); (decode) = LangSplat's (latent decoded to CLIP space).")
    t = Table(table_id, title, caption + " Overall = mean over scenes.", ["Method"], columns, rows)
    t.bold_best_per_column()
    return [_finish(t, mixed)]


def removal_table(res: Results) -> list[Table]:
    ids = res.run_ids(study=MAIN_STUDIES)
    metrics = ["removal_residual", "removal_psnr_outside"]
    if not ids or not any(res.has_metric(ids, m) for m in metrics):
        return []
    return _method_scene_table(res, ids, metrics, "removal", "3D object removal",
                               "Object removal by pruning (synthetic scenes with removal ground truth): "
                               "share of object pixels left and PSNR outside the object.")


def _method_scene_table(
    res: Results, ids: list[str], metrics: list[str], tid: str, title: str, caption: str
) -> list[Table]:
    pairs = scene_protocols(res, ids)
    columns = []
    for sc, _pr in pairs:
        for m in metrics:
            sp = _spec_for(m)
            columns.append(Column(m, sp.label, sp.latex, sp.better, group=sc))
    rows, mixed = [], []
    for meth in ordered_methods(res.distinct("method", ids)):
        cells = []
        for sc, pr in pairs:
            rids = res.run_ids(study=MAIN_STUDIES, method=meth, scene=sc, protocol=pr)
            for m in metrics:
                cells.append(_cell(res, rids, m, mixed, f"{sc}/{meth}"))
        rows.append(Row([method_label(meth)], cells))
    t = Table(tid, title, caption, ["Method"], columns, rows)
    t.bold_best_per_column()
    return [_finish(t, mixed)]


def _slug(s: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in str(s))


def _get(res: Results, rid: str, col: str) -> Any:
    if col not in res.runs.columns:
        return None
    v = res.runs.at[rid, col]
    return None if is_null(v) else v


def _eq_filter(eq: dict, methods: list) -> dict:
    out = dict(eq)
    if "method" not in out and len(methods) == 1:
        out["method"] = methods[0]
    return out


def _combo_text(keys: list[str], combo: tuple) -> str:
    return ",".join(f"{k.replace('axis.', '')}={_axis_label(k, v)}" for k, v in zip(keys, combo))
