"""The ablation tables: one row per setting of the study's grid axes, one column per (scene, metric),
and, for studies with a reference row, a second table with each row's difference from it.

Rows whose runs are one resolved configuration (the resolver dropped the setting that told them
apart, e.g. L_depth on a scene without a depth prior) are merged into one row and labelled.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from gsbench.config import config_key
from gsbench.methods.gaussiands.study_table import MAIN_STUDIES
from gsbench.methods.registry import method_sort_key
from gsbench.reports.data import Results, is_null, mean_of_cells, same

from gsbench.reports.display import (AX_FORMULATION, AX_LATENT, AX_LOSSES, AX_NOISE_SEVERITY, AX_NOISE_TYPE,  # isort: skip
                                  AX_ORDERING, LOSS_SUBSET_ORDER, REFERENCE_TEXT, STUDIES,
                                  STUDY_REFERENCE, method_label, metric_spec)
from gsbench.reports.stats import compare

from gsbench.reports.studies import (PROTOCOL_ORDER, PROTOCOL_SHORT, _axis_label, _axis_rank, _cell,  # isort: skip
                                     _combo_text, _eq_filter, _finish, _get, _slug, _spec_for, ordered_methods, runs_of,
                                     scene_protocols)
from gsbench.reports.table import CHECK, Cell, Column, Row, Table

DROPPED_COLUMN = "dropped"
_NO_CONFIG = config_key(None)  # the config_key of a results.json without a config


# ---------------------------------------------------------------------------- dropped settings
def parse_dropped(text: Any) -> dict[str, str]:
    """The collected `dropped` text ("key: reason; key2: reason2", "" when none) as a dict."""
    out: dict[str, str] = {}
    if is_null(text) or not str(text).strip():
        return out
    for part in str(text).split("; "):
        key, _, reason = part.partition(": ")
        if key.strip():
            out[key.strip()] = reason.strip()
    return out


def run_dropped(res: Results, rid: str) -> dict[str, str]:
    return parse_dropped(_get(res, rid, DROPPED_COLUMN))


def _covered(axis: str, dropped: dict[str, str]) -> str | None:
    """The reason when the resolver dropped this axis' setting (the key itself or a parent of it)."""
    key = axis.replace("axis.", "", 1)
    for d, why in dropped.items():
        if key == d or key.startswith(d + "."):
            return why
    return None


def _effective(res: Results, rid: str, keys: list[str]) -> tuple:
    """Axis values as the run really trained: a dropped boolean setting is off, any other dropped
    setting is unset."""
    dropped = run_dropped(res, rid)
    out = []
    for k in keys:
        v = _get(res, rid, k)
        if k.startswith("axis.") and _covered(k, dropped) is not None:
            v = False if isinstance(v, bool) else None
        out.append(v)
    return tuple(out)


def _same_combo(a: tuple, b: tuple) -> bool:
    return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))


def _one_per_seed(res: Results, rids: list[str]) -> list[str]:
    """Merged rows hold the same configuration twice per seed; keep the first run of each seed."""
    seen, out = set(), []
    for r in rids:
        s = _get(res, r, "seed")
        key = r if s is None else int(s)
        if key not in seen:
            seen.add(key)
            out.append(r)
    return out


def _group_combos(res: Results, ids: list[str], keys: list[str], combos: list[tuple]) -> list[list[tuple]]:
    """Combos whose runs share one resolved config (same config_key set, or the same axis values once
    dropped settings are applied) form one group; other combos stand alone."""
    groups: list[tuple[list[tuple], Any, Any]] = []  # (combos, effective combo, config keys)
    for c in combos:
        rids = [r for r in ids if _same_combo(tuple(_get(res, r, k) for k in keys), c)]
        effs = [_effective(res, r, keys) for r in rids]
        eff = effs[0] if effs and all(_same_combo(e, effs[0]) for e in effs) else None
        keys_of = [_get(res, r, "config_key") for r in rids]
        # a run without a recorded config hashes like every other such run: no evidence of sameness
        cks = frozenset(map(str, keys_of)) if keys_of and all(k and k != _NO_CONFIG for k in keys_of) else None
        for g in groups:
            if (eff is not None and g[1] is not None and _same_combo(eff, g[1])) or (cks and cks == g[2]):
                g[0].append(c)
                break
        else:
            groups.append(([c], eff, cks))
    return [g[0] for g in groups]


# ---------------------------------------------------------------------------- the tables
def _sorted_combos(res: Results, ids: list[str], keys: list[str], n_method: int, n_axes: int,
                   row_sort: Callable[[tuple], Any] | None) -> list[tuple]:
    """The distinct combos of `keys` over the runs, in row order: method, then the study's axes (by
    `row_sort` when given, else by axis rank), then any unexpected varying axis."""
    combos: list[tuple] = []
    for rid in ids:
        combo = tuple(_get(res, rid, k) for k in keys)
        if not any(_same_combo(combo, c) for c in combos):
            combos.append(combo)

    def default_sort(combo: tuple) -> tuple:
        out = []
        for k, v in zip(keys, combo):
            out.append(method_sort_key(v) if k == "method" else _axis_rank(k, v))
        return tuple(out)

    if row_sort is None:
        combos.sort(key=default_sort)
    else:
        combos.sort(key=lambda c: (default_sort(c)[:n_method], row_sort(c[n_method:n_method + n_axes]),
                                   default_sort(c)[n_method + n_axes:]))
    return combos


@dataclass
class _ColumnPlan:
    """The table's columns: one per evaluated (scene, protocol, metric), then the per-protocol means."""

    pairs: list[tuple[str, Any]]                      # (scene, protocol) of the study's runs
    group_cols: list[tuple[str, Any, str]]            # (scene, protocol, logical metric)
    mean_groups: list[tuple[Any, str, list[str]]]     # (protocol, logical metric, scenes averaged)
    columns: list[Column]
    not_evaluated: list[str]


def _column_plan(res: Results, ids: list[str], metrics: list[str]) -> _ColumnPlan | None:
    """The columns of the metrics evaluated on each scene (None when none is); the others are listed
    for the table's note."""
    pairs = scene_protocols(res, ids)
    group_cols: list[tuple[str, Any, str]] = []  # (scene, protocol, logical metric)
    not_evaluated = []
    for sc, pr in pairs:
        sids = runs_of(res, ids, sc, pr)
        for m in metrics:
            concrete = res.resolve(m, pr)
            if concrete is None or not res.has_metric(sids, concrete):
                not_evaluated.append(f"{metric_spec(m).label.replace(' (%)', '')} on {sc}")
                continue
            group_cols.append((sc, pr, m))
    if not group_cols:
        return None
    multi = len(pairs) > 1
    columns = []
    for sc, _pr, m in group_cols:
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
    return _ColumnPlan(pairs, group_cols, mean_groups, columns, not_evaluated)


def _label_maker(row_axes: list[str], extra: list[str], n_method: int, checks: bool,
                 row_labels: Callable[[tuple], list[str]] | None
                 ) -> Callable[[tuple], tuple[list[str], list[bool] | None]]:
    """combo -> (row labels: method, the study's axes, extra axes; the check marks of a checks table)."""
    def label_of(combo: tuple) -> tuple[list[str], list[bool] | None]:
        axis_vals = combo[n_method:n_method + len(row_axes)]
        labels = row_labels(axis_vals) if row_labels else [_axis_label(k, v) for k, v in zip(row_axes, axis_vals)]
        if checks:
            labels = [CHECK if (not is_null(v) and bool(v)) else "" for v in axis_vals]
        prefix = [method_label(combo[0])] if n_method else []
        extra_l = [_axis_label(k, v) for k, v in zip(extra, combo[n_method + len(row_axes):])]
        checks_l = [bool(v) if not is_null(v) else False for v in axis_vals] if checks else None
        return prefix + labels + extra_l, checks_l
    return label_of


def _ablation_rows(res: Results, ids: list[str], keys: list[str], groups: list[list[tuple]], plan: _ColumnPlan,
                   label_of: Callable, row_runs: Callable, mixed: list, any_dropped: bool,
                   plain_checks: bool) -> list[Row]:
    """One row per group of combos: merged groups join their differing labels and say why they are one
    configuration; with any dropped setting, a last label lists what the resolver dropped."""
    rows = []
    for group in groups:
        labels, checks_l = label_of(group[0])
        if len(group) > 1:
            alts = [label_of(c)[0] for c in group]
            labels = ["/".join(dict.fromkeys(a[i] or "–" for a in alts)) if len({a[i] for a in alts}) > 1 else labels[i]
                      for i in range(len(labels))]
        cells, by = [], {}
        for sc, pr, m in plan.group_cols:
            rids = row_runs(group, sc, pr)
            c = _cell(res, rids, res.resolve(m, pr), mixed, f"{sc}/{_combo_text(keys, group[0])}", _spec_for(m))
            by[(sc, m)] = c
            cells.append(c)
        for _pr, m, scs in plan.mean_groups:
            cells.append(mean_of_cells([by[(sc, m)] for sc in scs], scs, _spec_for(m).decimals))
        group_ids = [r for r in ids if any(_same_combo(tuple(_get(res, r, k) for k in keys), c) for c in group)]
        reasons = list(dict.fromkeys(why for r in group_ids for why in run_dropped(res, r).values()))
        if len(group) > 1:
            labels[-1] += " (merged: " + ("; ".join(reasons) or "same resolved config") + ")"
        if any_dropped:
            labels.append(
                "; ".join(dict.fromkeys(f"{k}: {v}" for r in group_ids for k, v in run_dropped(res, r).items()))
            )
        rows.append(Row(labels, cells, label_checks=checks_l if plain_checks else None))
    return rows


def ablation_table(res: Results, study: str, tid: str, title: str, caption: str, row_axes: list[str],
                   label_headers: list[str], metrics: list[str], checks: bool = False,
                   row_sort: Callable[[tuple], Any] | None = None,
                   row_labels: Callable[[tuple], list[str]] | None = None,
                   label_headers_latex: list[str] | None = None) -> list[Table]:
    """Rows = distinct values of the study's axes (plus method and any unexpected varying axis),
    column groups = scenes (with a mean over the scenes of each protocol), columns = metrics.
    Logical metrics ('miou', 'mbiou') resolve per protocol; best per column bold. Followed by the
    difference table when the study has a reference row."""
    ids = res.run_ids(study=study)
    if not ids:
        return []
    methods = ordered_methods(res.distinct("method", ids))
    # axis.method (a grid cell that sets the method) repeats the method column when there is one
    extra = [c for c in res.axis_columns if c not in row_axes and len(res.distinct(c, ids)) > 1
             and not (c == "axis.method" and len(methods) > 1)]
    keys = ["method"] * (len(methods) > 1) + row_axes + extra
    n_method = 1 if len(methods) > 1 else 0
    combos = _sorted_combos(res, ids, keys, n_method, len(row_axes), row_sort)
    groups = _group_combos(res, ids, keys, combos)

    plan = _column_plan(res, ids, metrics)
    if plan is None:
        return []
    pairs = plan.pairs
    multi = len(pairs) > 1

    def row_runs(group: list[tuple], sc: str, pr: Any) -> list[str]:
        rids: list[str] = []
        for combo in group:
            rids += res.run_ids(study=study, scene=sc, protocol=pr, **_eq_filter(dict(zip(keys, combo)), methods))
        return _one_per_seed(res, rids) if len(group) > 1 else rids

    any_dropped = any(run_dropped(res, r) for r in ids)
    merged_any = any(len(g) > 1 for g in groups)
    plain_checks = checks and not (n_method or extra or merged_any or any_dropped)
    mixed: list = []
    rows = _ablation_rows(res, ids, keys, groups, plan, _label_maker(row_axes, extra, n_method, checks, row_labels),
                          row_runs, mixed, any_dropped, plain_checks)
    row_groups = list(groups)
    heads = (["Method"] if n_method else []) + label_headers + [k.replace("axis.", "") for k in extra]
    if any_dropped:
        heads.append("Dropped by the resolver")
    cap = caption
    if not multi and pairs:
        cap += f" Scene: {pairs[0][0]} ({PROTOCOL_SHORT.get(pairs[0][1], pairs[0][1])})."
    t = Table(tid, title, cap, heads, plan.columns, rows, label_is_check=plain_checks)
    if label_headers_latex and plain_checks:
        t.label_headers_latex = label_headers_latex
    if plan.not_evaluated:
        t.notes.append("Not evaluated, column left out: " + ", ".join(plan.not_evaluated) + ".")
    if merged_any:
        t.notes.append("Rows labelled 'merged' are one resolved configuration: the resolver dropped the setting "
                       "that told their grid cells apart, so they were trained and evaluated alike.")
    t.bold_best_per_column()
    out = [_finish(t, mixed)]
    diff = diff_table(res, study, t, keys, row_groups, plan.group_cols, row_runs)
    if diff is not None:
        out.append(diff)
    return out


def _reference_group(study: str, keys: list[str], group: list[tuple], groups: list[list[tuple]]) -> int | None:
    """Index of the group holding this row's reference: its combo with the study's reference values."""
    ref = STUDY_REFERENCE.get(study, {})
    target = tuple(ref[k] if k in ref else v for k, v in zip(keys, group[0]))
    for i, g in enumerate(groups):
        if any(_same_combo(c, target) for c in g):
            return i
    return None


def diff_table(res: Results, study: str, table: Table, keys: list[str], groups: list[list[tuple]],
               group_cols: list[tuple[str, Any, str]], row_runs: Callable) -> Table | None:
    """Each row minus its reference row per (scene, metric), with the 95 % interval (paired by seed when
    both rows have the same seeds, else Welch); '*' marks an interval that excludes zero."""
    if study not in STUDY_REFERENCE:
        return None
    rows = []
    for row, group in zip(table.rows, groups):
        ri = _reference_group(study, keys, group, groups)
        cells = []
        for sc, pr, m in group_cols:
            if ri is None:
                cells.append(Cell(text="n/a (reference not run)"))
                continue
            if groups[ri] is group:
                cells.append(Cell(text="reference"))
                continue
            sp = _spec_for(m)
            concrete = res.resolve(m, pr)
            d = compare(res.seed_values(row_runs(group, sc, pr), concrete, sp.scale),
                        res.seed_values(row_runs(groups[ri], sc, pr), concrete, sp.scale))
            cells.append(Cell(text=d.text(sp.decimals)))
        rows.append(Row(list(row.labels), cells, label_checks=row.label_checks))
    cols = [Column(c.metric, "Δ " + c.label, "$\\Delta$ " + c.latex, None, group=c.group)
            for c in table.columns[:len(group_cols)]]
    ref_text = REFERENCE_TEXT.get(study, "the study's reference setting")
    return Table(f"{table.id}_diff", f"{table.title}: difference from the reference",
                 f"Each row minus the reference row, {ref_text}, in display units: mean difference "
                 "[95 % confidence interval] (n). Paired by seed when both rows ran the same seeds (same seed = "
                 "same initialisation and priors), else Welch's t; n/a with one seed. * = the interval excludes zero.",
                 list(table.label_headers), cols, rows, label_is_check=table.label_is_check,
                 label_headers_latex=table.label_headers_latex, section=table.section)


def ordering_table(res: Results) -> list[Table]:
    return ablation_table(
        res, "ordering", "ordering", "Pseudo-video ordering",
        "Ordering strategies for the pseudo-video: mean adjacent camera-centre distance, mean "
        "adjacent mask IoU of the propagated masks (new tracks count as misses), and what the "
        "supervision they give does to segmentation.",
        [AX_ORDERING], ["Ordering strategy"], ["ordering_adjacent_distance", "ordering_adjacent_mask_iou_strict",
                                              "ordering_adjacent_mask_iou_flow", "miou", "mbiou"])


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


def method_diff_table(res: Results) -> list[Table]:
    """The reconstruction grid's methods against GaussianDS (difference table only: the values are in
    Tables I-III)."""
    ts = ablation_table(
        res,
        "reconstruction",
        "reconstruction_methods",
        "Methods",
        "Methods of the reconstruction grid.",
        [],
        [],
        ["psnr", "ssim", "lpips", "miou", "mbiou"],
    )
    return [t for t in ts if t.id.endswith("_diff")]


def latent_diff_table(res: Results) -> list[Table]:
    """Each latent dimension (and the vanilla reference) against d = 3 (difference table only: the values
    are in the transposed latent-d table)."""
    ts = ablation_table(res, "latent_dim", "latent_dim_rows", "Latent dimension d", "Latent dimension d.",
                        [AX_LATENT], ["d"], ["miou", "psnr", "train_s"])
    return [t for t in ts if t.id.endswith("_diff")]


def other_study_tables(res: Results) -> list[Table]:
    """A study without a paper layout (e.g. the `tiny-test` grid): rows = its varying axes,
    columns = the usual reconstruction and segmentation metrics that its runs carry."""
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
