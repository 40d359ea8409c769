"""Build the paper's tables from the collected results, one builder per experiment.

Cell = all runs of one configuration (method, scene, protocol, grid-axis values) that differ only by
seed: mean +- sample std over seeds. Runs evaluated under different protocols are never averaged
(protocol is part of every cell, and tables are sectioned or grouped by protocol). A cell whose runs
differ by more than seed (config hash or providers) is still averaged but named in a table note.
Builders return [] when the study has no runs, so a report shows only the tables that have data.
"""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from gsbench.reports.data import MAIN_STUDIES, Results, is_null, mean_of_cells, same
from gsbench.reports.spec import (
    AX_FORMULATION, AX_LAMBDAS, AX_LATENT, AX_LOSSES, AX_NOISE_SEVERITY, AX_NOISE_TYPE, AX_ORDERING,
    FORMULATION_LABELS, FORMULATION_ORDER, LOSS_SUBSET_ORDER, METHOD_ORDER, NOISE_LABELS, NOISE_ORDER,
    ORDERING_LABELS, ORDERING_ORDER, PROTOCOL_LABELS, MetricSpec, method_label, metric_spec,
)
from gsbench.reports.table import Cell, Column, Row, Table, _mark, _tex

PROTOCOL_ORDER = ["3dovs", "lerf", None]
PROTOCOL_SHORT = {"3dovs": "3D-OVS", "lerf": "LERF-OVS", None: "no protocol"}


# ---------------------------------------------------------------------------- helpers
def _protocol_rank(p: Any) -> int:
    p = None if is_null(p) else p
    return PROTOCOL_ORDER.index(p) if p in PROTOCOL_ORDER else len(PROTOCOL_ORDER)


def ordered_methods(methods: list) -> list:
    from gsbench.methods.registry import method_sort_key
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


def _method_scene_table(res: Results, ids: list[str], metrics: list[str], tid: str, title: str, caption: str) -> list[Table]:
    pairs = scene_protocols(res, ids)
    columns = []
    for sc, pr in pairs:
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


# ---------------------------------------------------------------------------- ablations
def ablation_table(res: Results, study: str, tid: str, title: str, caption: str, row_axes: list[str],
                   label_headers: list[str], metrics: list[str], checks: bool = False,
                   row_sort: Callable[[tuple], Any] | None = None,
                   row_labels: Callable[[tuple], list[str]] | None = None,
                   label_headers_latex: list[str] | None = None) -> list[Table]:
    """Rows = distinct values of the study's axes (plus method and any unexpected varying axis),
    column groups = scenes (with a mean over the scenes of each protocol), columns = metrics.
    Logical metrics ('miou', 'mbiou') resolve per protocol; best per column bold."""
    ids = res.run_ids(study=study)
    if not ids:
        return []
    extra = [c for c in res.axis_columns if c not in row_axes and len(res.distinct(c, ids)) > 1]
    methods = ordered_methods(res.distinct("method", ids))
    keys = ["method"] * (len(methods) > 1) + row_axes + extra
    combos: list[tuple] = []
    for rid in ids:
        combo = tuple(_get(res, rid, k) for k in keys)
        if not any(all(same(a, b) for a, b in zip(combo, c)) for c in combos):
            combos.append(combo)

    def default_sort(combo: tuple) -> tuple:
        out = []
        for k, v in zip(keys, combo):
            out.append((METHOD_ORDER.index(v) if v in METHOD_ORDER else 9, str(v)) if k == "method" else _axis_rank(k, v))
        return tuple(out)

    n_method = 1 if len(methods) > 1 else 0
    if row_sort is None:
        combos.sort(key=default_sort)
    else:
        combos.sort(key=lambda c: (default_sort(c)[:n_method], row_sort(c[n_method:n_method + len(row_axes)]),
                                   default_sort(c)[n_method + len(row_axes):]))

    pairs = scene_protocols(res, ids)
    group_cols: list[tuple[str, Any, str]] = []  # (scene, protocol, concrete metric)
    dropped = []
    for sc, pr in pairs:
        sids = runs_of(res, ids, sc, pr)
        for m in metrics:
            concrete = res.resolve(m, pr)
            if concrete is None or not res.has_metric(sids, concrete):
                dropped.append(f"{metric_spec(m).label.replace(' (%)', '')} on {sc}")
                continue
            group_cols.append((sc, pr, m))
    if not group_cols:
        return []
    multi = len(pairs) > 1
    columns = []
    for sc, pr, m in group_cols:
        sp = _spec_for(m)
        columns.append(Column(m, sp.label, sp.latex, sp.better, group=sc if multi else None))
    # mean over the scenes of one protocol (never across protocols)
    mean_groups: list[tuple[Any, str, list[str]]] = []
    for pr in PROTOCOL_ORDER:
        scs = [sc for sc, p in pairs if same(p, pr)]
        if len(scs) < 2:
            continue
        for m in metrics:
            have = [sc for sc, p, mm in group_cols if same(p, pr) and mm == m]
            if len(have) >= 2:
                mean_groups.append((pr, m, have))
                sp = _spec_for(m)
                columns.append(Column(m, sp.label, sp.latex, sp.better, group=f"Mean ({PROTOCOL_SHORT.get(pr, pr)})"))

    rows, mixed = [], []
    for combo in combos:
        eq = dict(zip(keys, combo))
        cells, by = [], {}
        for sc, pr, m in group_cols:
            rids = res.run_ids(study=study, scene=sc, protocol=pr, **_eq_filter(eq, methods))
            c = _cell(res, rids, res.resolve(m, pr), mixed, f"{sc}/{_combo_text(keys, combo)}", _spec_for(m))
            by[(sc, m)] = c
            cells.append(c)
        for pr, m, scs in mean_groups:
            cells.append(mean_of_cells([by[(sc, m)] for sc in scs], scs, _spec_for(m).decimals))
        axis_vals = combo[n_method:n_method + len(row_axes)]
        labels = row_labels(axis_vals) if row_labels else [_axis_label(k, v) for k, v in zip(row_axes, axis_vals)]
        checks_l = None
        if checks:
            checks_l = [bool(v) for v in axis_vals]
        prefix = [method_label(combo[0])] if n_method else []
        extra_l = [_axis_label(k, v) for k, v in zip(extra, combo[n_method + len(row_axes):])]
        if checks:
            rows.append(Row(prefix + labels + extra_l, cells, label_checks=None if (prefix or extra_l) else checks_l))
            if prefix or extra_l:  # mixed label kinds: write check marks as text
                rows[-1].labels = prefix + [("✓" if v else "") for v in checks_l] + extra_l
        else:
            rows.append(Row(prefix + labels + extra_l, cells))
    heads = (["Method"] if n_method else []) + label_headers + [k.replace("axis.", "") for k in extra]
    cap = caption
    if not multi and pairs:
        cap += f" Scene: {pairs[0][0]} ({PROTOCOL_SHORT.get(pairs[0][1], pairs[0][1])})."
    t = Table(tid, title, cap, heads, columns, rows, label_is_check=checks and not (n_method or extra))
    if label_headers_latex and not (n_method or extra):
        t.label_headers_latex = label_headers_latex
    if dropped:
        t.notes.append("Not evaluated, column left out: " + ", ".join(dropped) + ".")
    t.bold_best_per_column()
    return [_finish(t, mixed)]


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


def ordering_table(res: Results) -> list[Table]:
    return ablation_table(
        res, "ordering", "ordering", "Pseudo-video ordering",
        "Ordering strategies for the pseudo-video: mean adjacent camera-centre distance and mean "
        "adjacent mask IoU of the propagated masks.",
        [AX_ORDERING], ["Ordering strategy"], ["ordering_adjacent_distance", "ordering_adjacent_mask_iou"])


def depth_formulation_table(res: Results) -> list[Table]:
    return ablation_table(
        res, "depth_formulation", "depth_formulation", "Depth supervision formulation",
        "Ablation of the depth supervision formulation.",
        [AX_FORMULATION], ["Depth supervision formulation"], ["ssim", "psnr", "lpips", "miou", "mbiou"])


def loss_subsets_table(res: Results) -> list[Table]:
    def order(vals: tuple) -> int:
        key = tuple(bool(v) if not is_null(v) else False for v in vals)
        return LOSS_SUBSET_ORDER.index(key) if key in LOSS_SUBSET_ORDER else 99
    return ablation_table(
        res, "loss_subsets", "loss_subsets", "Loss subsets",
        "Ablation of the loss components L_depth, L_tv and L_ds (check mark = term on).",
        AX_LOSSES, ["L_depth", "L_tv", "L_ds"], ["psnr", "miou"], checks=True, row_sort=order,
        label_headers_latex=["$\\mathcal{L}_{\\mathrm{depth}}$", "$\\mathcal{L}_{\\mathrm{tv}}$",
                             "$\\mathcal{L}_{\\mathrm{ds}}$"])


def noise_table(res: Results) -> list[Table]:
    def labels(vals: tuple) -> list[str]:
        kind, sev = vals
        if is_null(kind):
            return ["clean (no noise)", _axis_label(AX_NOISE_SEVERITY, sev if not is_null(sev) else 0)]
        return [_axis_label(AX_NOISE_TYPE, kind), _axis_label(AX_NOISE_SEVERITY, sev)]
    return ablation_table(
        res, "depth_noise", "depth_noise", "Depth-noise robustness",
        "Noise injected into the depth prior only, by kind and severity (0 = clean).",
        [AX_NOISE_TYPE, AX_NOISE_SEVERITY], ["Noise", "Severity"], ["psnr", "ssim", "lpips", "miou"],
        row_labels=labels)


# ---------------------------------------------------------------------------- latent d
LATENT_ROWS = ["train_s", "peak_rss_mb", "miou", "psnr"]


def latent_rows(res: Results, ids: list[str]) -> list[str]:
    """Time, memory (the training process's peak when recorded, else the evaluation's; CUDA too when
    recorded), mIoU, PSNR."""
    mem = "train_peak_rss_mb" if res.has_metric(ids, "train_peak_rss_mb") else "peak_rss_mb"
    rows = ["train_s", mem]
    if res.has_metric(ids, "train_peak_cuda_mb"):
        rows.append("train_peak_cuda_mb")
    return rows + ["miou", "psnr"]


def latent_dim_tables(res: Results) -> list[Table]:
    """Transposed like the paper: columns d = 3, 6, ... and the vanilla reference; rows time,
    memory, mIoU, PSNR; best per row bold. One table per scene."""
    ids = res.run_ids(study="latent_dim")
    if not ids:
        return []
    tables = []
    for sc, pr in scene_protocols(res, ids):
        sids = runs_of(res, ids, sc, pr)
        cols: list[tuple[str, Any]] = []  # (method, d)
        for rid in sids:
            meth = res.runs.at[rid, "method"]
            d = _get(res, rid, AX_LATENT) if meth == "gaussiands" else None
            if not any(m == meth and same(d, x) for m, x in cols):
                cols.append((meth, d))
        cols.sort(key=lambda t: (t[0] != "gaussiands", float(t[1]) if t[1] is not None else math.inf, str(t[0])))
        columns = []
        for meth, d in cols:
            lab = (_axis_label(AX_LATENT, d) if d is not None else "default") if meth == "gaussiands" else method_label(meth)
            columns.append(Column("d", lab, _tex(lab), None))
        rows, mixed = [], []
        for m in latent_rows(res, sids):
            sp = _spec_for(m)
            cells = []
            for meth, d in cols:
                rids = [r for r in sids if res.runs.at[r, "method"] == meth
                        and (meth != "gaussiands" or same(_get(res, r, AX_LATENT), d))]
                cells.append(_cell(res, rids, res.resolve(m, pr), mixed, f"{sc}/{meth}/d={d}", sp))
            rows.append(Row([sp.label], cells))
            _mark(cells, sp.better)
        t = Table(f"latent_dim_{_slug(sc)}", f"Latent dimension d ({sc})",
                  f"Segmentation accuracy and cost across latent dimensions d on {sc} "
                  f"({PROTOCOL_SHORT.get(pr, pr)}); memory is the peak resident set size of the process "
                  "(CPU RAM, not VRAM, unless a CUDA row is shown). Best per row in bold.",
                  ["Latent dimension d"], columns, rows)
        tables.append(_finish(t, mixed))
    return tables


# ---------------------------------------------------------------------------- lambda grid
def pearson(x: list[float], y: list[float]) -> tuple[float | None, str | None]:
    """Pearson r with its undefined cases named instead of NaN."""
    xa, ya = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    ok = np.isfinite(xa) & np.isfinite(ya)
    xa, ya = xa[ok], ya[ok]
    if xa.size < 3:
        return None, f"{xa.size} runs with values (need 3)"
    sx, sy = float(np.std(xa)), float(np.std(ya))
    if sx == 0.0:
        return None, "lambda constant"
    if sy == 0.0:
        return None, "metric constant"
    xc, yc = xa - xa.mean(), ya - ya.mean()
    denom = math.sqrt(float(np.sum(xc * xc)) * float(np.sum(yc * yc)))
    if denom <= 0.0:
        return None, "zero variance"
    return float(np.clip(np.sum(xc * yc) / denom, -1.0, 1.0)), None


def lambda_points(res: Results, scene: str, protocol: Any, axis: str, metric: str) -> tuple[list[float], list[float]]:
    """(lambda value, metric) per done run of the lambda grid on one scene."""
    xs, ys = [], []
    concrete = res.resolve(metric, protocol)
    if concrete is None or axis not in res.runs.columns:
        return xs, ys
    for rid in res.run_ids(study="lambda_grid", scene=scene, protocol=protocol):
        if res.runs.at[rid, "status"] != "done":
            continue
        lam = res.runs.at[rid, axis]
        v = res.value(rid, concrete)
        if is_null(lam) or not math.isfinite(v):
            continue
        xs.append(float(lam))
        ys.append(v)
    return xs, ys


def lambda_table(res: Results) -> list[Table]:
    ids = res.run_ids(study="lambda_grid")
    if not ids:
        return []
    axes = [a for a in AX_LAMBDAS if a in res.runs.columns and len(res.distinct(a, ids)) > 1]
    if not axes:
        return []
    pairs = scene_protocols(res, ids)
    columns = []
    for sc, pr in pairs:
        for m, lab in (("miou", "r with mIoU"), ("psnr", "r with PSNR")):
            columns.append(Column(m, lab, lab, None, group=sc if len(pairs) > 1 else None))
    rows = []
    for a in axes:
        cells = []
        for sc, pr in pairs:
            for m in ("miou", "psnr"):
                r, why = pearson(*lambda_points(res, sc, pr, a, m))
                cells.append(Cell(mean=r, n=1, total=1, decimals=3, reason=why))
        rows.append(Row(["λ_" + a.rsplit(".", 1)[-1], ", ".join(_axis_label(a, v) for v in sorted(res.distinct(a, ids), key=lambda v: float(v) if not is_null(v) else -1))], cells))
    cap = ("Pearson correlation of each lambda (raw value, one point per run, all other lambdas varying) "
           "with the final mIoU and PSNR of the lambda grid.")
    if len(pairs) == 1:
        cap += f" Scene: {pairs[0][0]}."
    return [Table("lambda_pearson", "Lambda sensitivity (Pearson r)", cap, ["Lambda", "Values"], columns, rows)]


def _slug(s: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in str(s))


def other_study_tables(res: Results) -> list[Table]:
    """A study without a paper layout (e.g. the `tiny-test` grid): rows = its varying axes,
    columns = the usual reconstruction and segmentation metrics that its runs carry."""
    from gsbench.reports.spec import STUDIES
    tables = []
    for st in sorted(s for s in res.studies() if s not in MAIN_STUDIES and s not in STUDIES):
        ids = res.run_ids(study=st)
        axes = [c for c in res.axis_columns if c != "axis.method" and len(res.distinct(c, ids)) > 1]
        ts = ablation_table(res, st, f"study_{_slug(st)}", f"Study '{st}'",
                            f"Runs of study '{st}' by grid axis (no paper layout for this study).",
                            axes, [a.replace("axis.", "") for a in axes], ["ssim", "psnr", "lpips", "miou", "mbiou"])
        for t in ts:
            t.section = f"other_{st}"
        tables += ts
    return tables


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
    tables += ordering_table(res)
    tables += depth_formulation_table(res)
    tables += loss_subsets_table(res)
    tables += latent_dim_tables(res)
    tables += lambda_table(res)
    tables += noise_table(res)
    tables += other_study_tables(res)
    return tables
