"""Studies laid out by their sweep rather than row-by-axis: the latent dimension d (transposed like
the paper: one column per d) and the lambda grid (Pearson r of each lambda with the metrics)."""
from __future__ import annotations

import math
from typing import Any

from gsbench.reports.data import Results, is_null, same
from gsbench.reports.display import AX_LAMBDAS, AX_LATENT, method_label
from gsbench.reports.stats import pearson, pearson_interval

from gsbench.reports.studies import (PROTOCOL_SHORT, _axis_label, _cell, _finish, _get, _slug, _spec_for,  # isort: skip
                                     runs_of, scene_protocols)
from gsbench.reports.table import Cell, Column, Row, Table, _mark, _tex

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
            lab = (
                (_axis_label(AX_LATENT, d) if d is not None else "default")
                if meth == "gaussiands"
                else method_label(meth)
            )
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
    for sc, _pr in pairs:
        for m, lab in (("miou", "r with mIoU"), ("psnr", "r with PSNR")):
            columns.append(Column(m, lab, lab, None, group=sc if len(pairs) > 1 else None))
    rows = []
    for a in axes:
        cells = []
        for sc, pr in pairs:
            for m in ("miou", "psnr"):
                xs, ys = lambda_points(res, sc, pr, a, m)
                r, why = pearson(xs, ys)
                ci = pearson_interval(r, len(xs)) if r is not None else None
                if r is None:
                    cells.append(Cell(decimals=3, total=1, reason=why))
                elif ci is None:
                    cells.append(Cell(text=f"{r:.3f} [n/a: {len(xs)} runs] (n={len(xs)})"))
                else:
                    mark = " *" if ci[0] > 0 or ci[1] < 0 else ""
                    cells.append(Cell(text=f"{r:.3f} [{ci[0]:.3f}, {ci[1]:.3f}]{mark} (n={len(xs)})"))
        rows.append(
            Row(
                [
                    "λ_" + a.rsplit(".", 1)[-1],
                    ", ".join(
                        _axis_label(a, v)
                        for v in sorted(res.distinct(a, ids), key=lambda v: float(v) if not is_null(v) else -1)
                    ),
                ],
                cells,
            )
        )
    cap = ("Pearson correlation of each lambda (raw value, one point per run, all other lambdas varying) "
           "with the final mIoU and PSNR of the lambda grid: r [95 % interval by Fisher's z] (runs); "
           "* = the interval excludes zero.")
    if len(pairs) == 1:
        cap += f" Scene: {pairs[0][0]}."
    return [Table("lambda_pearson", "Lambda sensitivity (Pearson r)", cap, ["Lambda", "Values"], columns, rows)]
