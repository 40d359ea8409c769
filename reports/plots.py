"""Report figures (matplotlib, Agg backend, PNG): error against run time with the Pareto front,
lambda response surfaces, metric vs depth-noise severity, the latent-d trade-off, and bar charts
of every table. Each function writes one PNG and returns its path, or None when there is no data.

Why these: people compare plots faster than tables; each figure has a title, axis labels with
units, a legend, and says which runs and scene it shows.
"""
from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from gsbench.reports.data import Results, is_null, same  # noqa: E402

from gsbench.reports.display import (AX_LAMBDAS, AX_LATENT, AX_NOISE_SEVERITY, AX_NOISE_TYPE,  # noqa: E402  # isort: skip
                                  LOGICAL, NOISE_LABELS, NOISE_ORDER, method_label, metric_spec)
from gsbench import rundir
from gsbench.reports.run_names import run_labels  # noqa: E402
from gsbench.reports.stats import pearson  # noqa: E402
from gsbench.reports.studies import PROTOCOL_SHORT, _get, _slug, runs_of, scene_protocols  # noqa: E402
from gsbench.reports.sweeps import (
    lambda_points,  # noqa: E402
    latent_rows,
)
from gsbench.reports.table import Table  # noqa: E402
from gsbench.store import read_jsonl, write_bytes_atomic  # noqa: E402

DPI = 100


def _save(fig, path: Path) -> Path:
    import io
    buf = io.BytesIO()
    if not fig.get_tight_layout():
        fig.tight_layout()
    fig.savefig(buf, format="png", dpi=DPI)
    plt.close(fig)
    write_bytes_atomic(path, buf.getvalue())
    return path


# ---------------------------------------------------------------------------- time curves
def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points not dominated when time (x) is minimised and the metric (y) maximised,
    sorted by time. A point is dominated if another has time <= and metric >= with one strict."""
    idx = []
    for i, (t, m) in enumerate(points):
        dominated = any((t2 <= t and m2 >= m) and (t2 < t or m2 > m) for j, (t2, m2) in enumerate(points) if j != i)
        if not dominated:
            idx.append(i)
    return sorted(idx, key=lambda i: (points[i][0], -points[i][1]))


def _miou_key(protocol: Any) -> str | None:
    return LOGICAL["miou"].get(None if is_null(protocol) else protocol)


def train_curve(run_dir: str, metric_keys: list[str]) -> tuple[list[float], list[float]]:
    """(wall seconds, metric) of the periodic evaluations in a run's train_log.jsonl; the first of
    metric_keys present in an eval entry is used (the results.json metric names). Phases (e.g.
    twostage's rgb then semantic) each restart wall_s; they are laid end to end."""
    xs, ys = [], []
    offset, phase, phase_end = 0.0, None, 0.0
    for rec in read_jsonl(Path(run_dir) / rundir.TRAIN_LOG):
        if not isinstance(rec, dict):
            continue
        wall = rec.get("wall_s")
        if not isinstance(wall, (int, float)) or isinstance(wall, bool) or not math.isfinite(wall):
            continue
        if rec.get("phase") != phase:  # a new training phase (twostage) restarts its clock
            if phase is not None:
                offset += phase_end
            phase, phase_end = rec.get("phase"), 0.0
        phase_end = max(phase_end, float(wall))
        wall = float(wall) + offset
        ev = rec.get("eval")
        if not isinstance(ev, dict):
            continue
        for k in metric_keys:
            v = ev.get(k)
            if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
                xs.append(float(wall))
                ys.append(float(v))
                break
    return xs, ys


def _final_time(res: Results, rid: str, curve_x: list[float]) -> float:
    t = res.value(rid, "train_s")
    if math.isfinite(t):
        return t
    return curve_x[-1] if curve_x else math.nan


def plot_time_curves(res: Results, study: Any, run_ids: list[str], path: Path) -> tuple[Path | None, list[str]]:
    """PSNR and mIoU against wall time for every run of a study (train_log.jsonl), with the final
    values (results.json) against total training time and, per scene, their Pareto front."""
    notes: list[str] = []
    panels = []
    for title, unit, keys_fn, final_fn, scale in (
        ("PSNR", "PSNR (dB)", lambda rid: ["psnr"], lambda rid: "psnr", 1.0),
        ("mIoU", "mIoU (%)", lambda rid: [k for k in (_miou_key(res.runs.at[rid, "protocol"]), "miou") if k],
         lambda rid: _miou_key(res.runs.at[rid, "protocol"]), 100.0),
    ):
        curves, finals = {}, {}
        for rid in run_ids:
            xs, ys = train_curve(res.runs.at[rid, "run_dir"], keys_fn(rid))
            if xs:
                curves[rid] = (xs, [y * scale for y in ys])
            fk = final_fn(rid)
            fv = res.value(rid, fk) if fk else math.nan
            ft = _final_time(res, rid, xs)
            if res.runs.at[rid, "status"] == "done" and math.isfinite(fv) and math.isfinite(ft):
                finals[rid] = (ft, fv * scale)
        if curves or finals:
            panels.append((title, unit, curves, finals))
            missing = [r for r in run_ids if r not in curves]
            if missing:
                notes.append(f"{title} over time: {len(missing)} of {len(run_ids)} run(s) have no periodic "
                             f"{title} in train_log.jsonl (final value only).")
    if not panels:
        return None, notes
    fig, axes = plt.subplots(1, len(panels), figsize=(6.6 * len(panels), 4.8), squeeze=False)
    many, labels = len(run_ids) > 10, run_labels(res, run_ids)
    cmap = plt.cm.tab10 if not many else plt.cm.viridis
    color = {rid: cmap(i % 10 / 9.0 if not many else i / max(len(run_ids) - 1, 1)) for i, rid in enumerate(run_ids)}
    front_colors = ["crimson", "darkorange", "purple", "saddlebrown", "teal", "olive"]
    for ax, (title, unit, curves, finals) in zip(axes[0], panels):
        for rid in run_ids:
            lab = None if many else labels[rid]
            if rid in curves:
                xs, ys = curves[rid]
                ax.plot(
                    xs,
                    ys,
                    "-",
                    color=color[rid],
                    lw=1.4 if not many else 0.8,
                    alpha=0.9 if not many else 0.6,
                    label=lab,
                )
                lab = None
            if rid in finals:
                ax.plot(*finals[rid], "o", color=color[rid], ms=6, mec="black", mew=0.6, label=lab)
        # one Pareto front per scene: final values of different scenes are not comparable
        scenes: list = []
        for rid in finals:
            if res.runs.at[rid, "scene"] not in scenes:
                scenes.append(res.runs.at[rid, "scene"])
        for si, sc in enumerate(scenes):
            ids = [rid for rid in finals if res.runs.at[rid, "scene"] == sc]
            pts = [finals[rid] for rid in ids]
            front = [ids[i] for i in pareto_front(pts)]
            fx = [finals[r][0] for r in front]
            fy = [finals[r][1] for r in front]
            fc = front_colors[si % len(front_colors)]
            lab = "Pareto front (final vs total time)" + (f", {sc}" if len(scenes) > 1 else "")
            ax.step(fx, fy, where="post", color=fc, lw=2.0, ls="--", label=lab)
            ax.plot(fx, fy, "D", color=fc, ms=9, mfc="none", mew=1.6)
            if many:
                for r in front:
                    ax.annotate(labels[r], finals[r], fontsize=6, xytext=(4, 4), textcoords="offset points")
        ax.set_xlabel("training wall time (s)")
        ax.set_ylabel(unit)
        ax.set_title(f"{title} over training time")
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7, loc="best")
    name = "standalone / reconstruction runs" if study is None else f"study '{study}'"
    fig.suptitle(f"Error against run time — {name} ({len(run_ids)} runs; lines: periodic eval, "
                 f"dots: final results vs total train time)", fontsize=11)
    return _save(fig, path), notes


# ---------------------------------------------------------------------------- lambda grid
def _mode(values: list) -> Any:
    """Most common value (first seen wins a tie): the grid's default of a lambda."""
    best, count = None, 0
    for v in values:
        c = sum(1 for w in values if same(v, w))
        if c > count:
            best, count = v, c
    return best


def _lambda_slice(res: Results, sids: list[str], axes_all: list[str], keep: list[str]) -> list[str]:
    """Runs whose lambdas other than `keep` sit at their most common value (the grid default), so a
    surface over `keep` is not averaged with runs of another sweep."""
    fixed = {a: _mode([_get(res, r, a) for r in sids]) for a in axes_all if a not in keep}
    return [r for r in sids if all(same(_get(res, r, a), v) for a, v in fixed.items())]


def _lambda_surfaces(res: Results, sids: list[str], axes_all: list[str], concrete: str) -> list[tuple]:
    """(a, b, a values, b values, mean metric (%) grid) of each lambda pair swept together: >= 75 % of the
    pair's cells have runs with the other lambdas at their grid default."""
    surfaces = []
    for a, b in itertools.combinations(axes_all, 2):
        sl = _lambda_slice(res, sids, axes_all, [a, b])
        av = sorted(float(v) for v in res.distinct(a, sl) if not is_null(v))
        bv = sorted(float(v) for v in res.distinct(b, sl) if not is_null(v))
        if len(av) < 2 or len(bv) < 2:
            continue
        grid = np.full((len(bv), len(av)), np.nan)
        for i, y in enumerate(bv):
            for j, x in enumerate(av):
                vals = [res.value(r, concrete) for r in sl if same(_get(res, r, a), x) and same(_get(res, r, b), y)]
                if vals:
                    grid[i, j] = float(np.mean(vals)) * 100.0
        if np.isfinite(grid).mean() >= 0.75:
            surfaces.append((a, b, av, bv, grid))
    return surfaces


def _draw_surface(fig, ax, grid: np.ndarray, av: list[float], bv: list[float], xlabel: str, ylabel: str,
                  title: str) -> None:
    """One surface as a heatmap, each cell annotated with its value (or 'no run'), with a colour bar."""
    im = ax.imshow(grid, origin="lower", cmap="viridis", aspect="auto")
    ax.set_xticks(range(len(av)), [f"{v:g}" for v in av])
    ax.set_yticks(range(len(bv)), [f"{v:g}" for v in bv])
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    finite = grid[np.isfinite(grid)]
    mid = (finite.min() + finite.max()) / 2
    for i in range(len(bv)):
        for j in range(len(av)):
            if np.isfinite(grid[i, j]):
                ax.text(j, i, f"{grid[i, j]:.1f}", ha="center", va="center", fontsize=8,
                        color="white" if grid[i, j] < mid else "black")
            else:
                ax.text(j, i, "no run", ha="center", va="center", fontsize=7, color="gray")
    fig.colorbar(im, ax=ax, label="mIoU (%)")


def plot_lambda_surfaces(res: Results, path_prefix: Path) -> list[Path]:
    """Per scene: mIoU over each pair of lambdas that was swept together (>= 75 % of the pair's
    cells filled, the other lambdas at their grid default) as an annotated heatmap; lambdas in no
    such pair get a response curve. The Pearson r of each lambda against mIoU (over all runs) is in
    the labels and title."""
    ids = res.run_ids(study="lambda_grid")
    out: list[Path] = []
    axes_all = [a for a in AX_LAMBDAS if a in res.runs.columns and len(res.distinct(a, ids)) > 1]
    if not ids or not axes_all:
        return out
    for sc, pr in scene_protocols(res, ids):
        concrete = res.resolve("miou", pr)
        if concrete is None:
            continue
        sids = [r for r in res.run_ids(study="lambda_grid", scene=sc, protocol=pr)
                if res.runs.at[r, "status"] == "done" and math.isfinite(res.value(r, concrete))]
        if not sids:
            continue
        r_of = {}
        for a in axes_all:
            r, why = pearson(*lambda_points(res, sc, pr, a, "miou"))
            r_of[a] = f"r={r:+.2f}" if r is not None else f"r n/a ({why})"
        short = {a: "λ_" + a.rsplit(".", 1)[-1] for a in axes_all}
        surfaces = _lambda_surfaces(res, sids, axes_all, concrete)
        in_pair = {x for a, b, *_ in surfaces for x in (a, b)}
        curves = [a for a in axes_all if a not in in_pair]
        n = len(surfaces) + len(curves)
        ncol = min(3, n)
        nrow = math.ceil(n / ncol)
        fig, axs = plt.subplots(nrow, ncol, figsize=(max(7.5, 5.2 * ncol), 4.3 * nrow + 0.6), squeeze=False)
        for k, (a, b, av, bv, grid) in enumerate(surfaces):
            _draw_surface(fig, axs[k // ncol][k % ncol], grid, av, bv, f"{short[a]} ({r_of[a]})",
                          f"{short[b]} ({r_of[b]})", f"mIoU (%) over {short[a]} × {short[b]}")
        for k, a in enumerate(curves, start=len(surfaces)):
            ax = axs[k // ncol][k % ncol]
            sl = _lambda_slice(res, sids, axes_all, [a])
            pts = [(float(_get(res, r, a)), res.value(r, concrete) * 100.0) for r in sl if _get(res, r, a) is not None]
            vals = sorted({x for x, _ in pts})
            ax.plot(vals, [np.mean([y for x, y in pts if x == v]) for v in vals], "o-", label="mean over seeds")
            ax.scatter([x for x, _ in pts], [y for _, y in pts], s=12, alpha=0.5, color="gray", label="runs")
            if len(vals) > 2 and min(vals) > 0 and max(vals) / min(vals) >= 20:
                ax.set_xscale("log")
            ax.set_xlabel(f"{short[a]} ({r_of[a]})")
            ax.set_ylabel("mIoU (%)")
            ax.set_title(f"mIoU vs {short[a]} (others at default)", fontsize=10)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
        for k in range(n, nrow * ncol):
            axs[k // ncol][k % ncol].set_axis_off()
        rs = ", ".join(f"{short[a]} {r_of[a]}" for a in axes_all)
        fig.suptitle(f"Lambda response surfaces on {sc} ({PROTOCOL_SHORT.get(pr, pr)})\n"
                     f"Pearson r with mIoU (all runs): {rs}", fontsize=11)
        out.append(_save(fig, Path(f"{path_prefix}_{_slug(sc)}.png")))
    return out


# ---------------------------------------------------------------------------- noise
NOISE_METRICS = ["psnr", "ssim", "lpips", "miou"]


def plot_noise(res: Results, path_prefix: Path) -> list[Path]:
    """Per scene: each metric against severity, one line per noise kind (severity 0 = the clean run)."""
    ids = res.run_ids(study="depth_noise")
    out = []
    if not ids:
        return out
    for sc, pr in scene_protocols(res, ids):
        sids = runs_of(res, ids, sc, pr, done_only=True)
        metrics = [m for m in NOISE_METRICS if res.resolve(m, pr) and
                   any(math.isfinite(res.value(r, res.resolve(m, pr))) for r in sids)]
        if not metrics:
            continue
        kinds = [k for k in res.distinct(AX_NOISE_TYPE, sids) if not is_null(k)]
        kinds.sort(key=lambda k: NOISE_ORDER.index(k) if k in NOISE_ORDER else 99)
        clean = [r for r in sids if is_null(_get(res, r, AX_NOISE_TYPE)) or
                 (not is_null(_get(res, r, AX_NOISE_SEVERITY)) and float(_get(res, r, AX_NOISE_SEVERITY)) == 0)]
        fig, axs = plt.subplots(1, len(metrics), figsize=(4.6 * len(metrics), 4.0), squeeze=False)
        for ax, m in zip(axs[0], metrics):
            concrete = res.resolve(m, pr)
            sp = metric_spec(m)
            base = [res.value(r, concrete) * sp.scale for r in clean]
            base = [v for v in base if math.isfinite(v)]
            for kind in kinds:
                pts: dict[float, list[float]] = {}
                if base:
                    pts[0.0] = list(base)
                for r in sids:
                    if not same(_get(res, r, AX_NOISE_TYPE), kind):
                        continue
                    sev = _get(res, r, AX_NOISE_SEVERITY)
                    v = res.value(r, concrete) * sp.scale
                    if sev is None or not math.isfinite(v):
                        continue
                    pts.setdefault(float(sev), []).append(v)
                if not pts:
                    continue
                xs = sorted(pts)
                mu = [float(np.mean(pts[x])) for x in xs]
                sd = [float(np.std(pts[x], ddof=1)) if len(pts[x]) > 1 else 0.0 for x in xs]
                ax.errorbar(
                    xs, mu, yerr=sd if any(sd) else None, marker="o", capsize=3, label=NOISE_LABELS.get(kind, str(kind))
                )
            if base and not kinds:
                ax.axhline(float(np.mean(base)), color="gray", ls="--", label="clean")
            arrow = {"higher": " (↑ better)", "lower": " (↓ better)"}.get(sp.better or "", "")
            ax.set_title(sp.label + arrow)
            ax.set_xlabel("noise severity (0 = clean)")
            ax.set_ylabel(sp.label)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=8)
        fig.suptitle(f"Metric vs depth-noise severity on {sc} ({PROTOCOL_SHORT.get(pr, pr)}); "
                     "error bars: std over seeds", fontsize=11)
        out.append(_save(fig, Path(f"{path_prefix}_{_slug(sc)}.png")))
    return out


# ---------------------------------------------------------------------------- latent d
def plot_latent(res: Results, path_prefix: Path) -> list[Path]:
    """Per scene: mIoU, PSNR, training time and peak memory against d, vanilla as a dashed line."""
    ids = res.run_ids(study="latent_dim")
    out = []
    if not ids:
        return out
    for sc, pr in scene_protocols(res, ids):
        sids = runs_of(res, ids, sc, pr, done_only=True)
        gids = [r for r in sids if res.runs.at[r, "method"] == "gaussiands" and _get(res, r, AX_LATENT) is not None]
        if not gids:
            continue
        ref = [r for r in sids if res.runs.at[r, "method"] != "gaussiands"]
        fig, axs = plt.subplots(2, 2, figsize=(10, 7.5))
        mem = latent_rows(res, sids)[1]
        for ax, m in zip(axs.flat, ["miou", "psnr", "train_s", mem]):
            concrete = res.resolve(m, pr)
            sp = metric_spec(m)
            if concrete is None:
                ax.set_axis_off()
                continue
            pts: dict[float, list[float]] = {}
            for r in gids:
                v = res.value(r, concrete) * sp.scale
                if math.isfinite(v):
                    pts.setdefault(float(_get(res, r, AX_LATENT)), []).append(v)
            if pts:
                xs = sorted(pts)
                mu = [float(np.mean(pts[x])) for x in xs]
                sd = [float(np.std(pts[x], ddof=1)) if len(pts[x]) > 1 else 0.0 for x in xs]
                ax.errorbar(xs, mu, yerr=sd if any(sd) else None, marker="o", capsize=3, label="GaussianDS")
                ax.set_xscale("log", base=2)
                ax.set_xticks(xs, [f"{x:g}" for x in xs])
            for meth in sorted({res.runs.at[r, "method"] for r in ref}):
                vals = [res.value(r, concrete) * sp.scale for r in ref if res.runs.at[r, "method"] == meth]
                vals = [v for v in vals if math.isfinite(v)]
                if vals:
                    ax.axhline(float(np.mean(vals)), color="gray", ls="--", label=method_label(meth))
            arrow = {"higher": " (↑ better)", "lower": " (↓ better)"}.get(sp.better or "", "")
            ax.set_title(sp.label + arrow)
            ax.set_xlabel("latent dimension d")
            ax.set_ylabel(sp.label)
            ax.grid(True, alpha=0.3)
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=8)
        fig.suptitle(f"Latent-d trade-off on {sc} ({PROTOCOL_SHORT.get(pr, pr)})", fontsize=12)
        out.append(_save(fig, Path(f"{path_prefix}_{_slug(sc)}.png")))
    return out


# ---------------------------------------------------------------------------- tables as bars
def plot_table_bars(table: Table, path: Path) -> Path | None:
    """One panel per metric; bars = table rows on the x axis, one colour per column group
    (method or scene); error bars = std over seeds. The bold (best) bars get a black edge."""
    metrics: list[str] = []
    for c in table.columns:
        if c.metric not in metrics:
            metrics.append(c.metric)
    panels = []
    for m in metrics:
        js = [j for j, c in enumerate(table.columns) if c.metric == m]
        if any(table.rows[i].cells[j].rounded() is not None for i in range(len(table.rows)) for j in js):
            panels.append((m, js))
    if not panels or not table.rows:
        return None
    ncol = min(3, len(panels))
    nrow = math.ceil(len(panels) / ncol)
    width = max(4.8, 0.5 * len(table.rows) * max(len(js) for _, js in panels) ** 0.5 + 2)
    fig, axs = plt.subplots(nrow, ncol, figsize=(width * ncol, 4.0 * nrow), squeeze=False)
    row_names = [" ".join(x for x in (r.labels if r.label_checks is None else
                 ["+".join(h for h, v in zip(table.label_headers, r.label_checks) if v) or "none"]) if x)
                 for r in table.rows]
    sections = [r.section for r in table.rows]
    if len(set(sections)) > 1:
        row_names = [f"{n}\n[{s}]" if s else n for n, s in zip(row_names, sections)]
    for k, (m, js) in enumerate(panels):
        ax = axs[k // ncol][k % ncol]
        nb = len(js)
        bw = 0.8 / nb
        x = np.arange(len(table.rows))
        for b, j in enumerate(js):
            col = table.columns[j]
            cells = [r.cells[j] for r in table.rows]
            h = [c.mean if c.rounded() is not None else 0.0 for c in cells]
            err = [c.std if (c.std is not None and c.rounded() is not None) else 0.0 for c in cells]
            label = col.group or col.label
            bars = ax.bar(x + (b - (nb - 1) / 2) * bw, h, bw, yerr=err if any(err) else None, capsize=2, label=label)
            for bar, c in zip(bars, cells):
                if c.bold:
                    bar.set_edgecolor("black")
                    bar.set_linewidth(1.6)
                if c.rounded() is None and c.reason:
                    ax.text(bar.get_x() + bar.get_width() / 2, 0, "n/a", rotation=90, ha="center",
                            va="bottom", fontsize=7, color="gray")
        first = table.columns[js[0]]
        sp = metric_spec(m)
        arrow = {"higher": " (↑ better)", "lower": " (↓ better)"}.get(first.better or "", "")
        ax.set_title(sp.label + arrow, fontsize=10)
        ax.set_ylabel(sp.label)
        ax.set_xticks(
            x,
            row_names,
            rotation=30 if len(table.rows) > 3 else 0,
            ha="right" if len(table.rows) > 3 else "center",
            fontsize=8,
        )
        ax.grid(True, axis="y", alpha=0.3)
        if nb > 1:
            ax.legend(fontsize=7)
    for k in range(len(panels), nrow * ncol):
        axs[k // ncol][k % ncol].set_axis_off()
    fig.suptitle(table.title + " (black edge = best)", fontsize=12)
    return _save(fig, path)
