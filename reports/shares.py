"""Plot of each weighted loss term's share of the total loss over training steps, per run cell.

Why: a lambda means something only relative to the other terms; the share shows whether a term
(e.g. L_depth at lambda 0.01) is a real part of the objective or a rounding error. The shares come
from the `loss_share` entries ({term: fraction}) of the runs' train_log.jsonl; runs that do not log
them are skipped with a note.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from gsbench import rundir
from gsbench.reports.data import Results, is_null  # noqa: E402
from gsbench.reports.plots import _save  # noqa: E402
from gsbench.reports.run_names import run_label  # noqa: E402
from gsbench.store import read_jsonl  # noqa: E402

MAX_PANELS = 12


def read_shares(run_dir: str) -> dict[int, dict[str, float]]:
    """step -> {term: share} from a run's train_log.jsonl (lines without a valid loss_share are ignored;
    a later line for the same step and phase replaces an earlier one)."""
    out: dict[int, dict[str, float]] = {}
    offset, phase, last = 0, None, 0
    for rec in read_jsonl(Path(run_dir) / rundir.TRAIN_LOG):
        if not isinstance(rec, dict):
            continue
        step = rec.get("step")
        if not isinstance(step, int) or isinstance(step, bool):
            continue
        if rec.get("phase") != phase:  # twostage: the semantic phase restarts its step count
            if phase is not None:
                offset += last
            phase, last = rec.get("phase"), 0
        last = max(last, step)
        sh = rec.get("loss_share")
        if not isinstance(sh, dict):
            continue
        vals = {str(k): float(v) for k, v in sh.items()
                if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)}
        if vals:
            out[step + offset] = vals
    return out


def _cells(res: Results, run_ids: list[str]) -> list[tuple[str, list[str]]]:
    """Runs grouped by configuration (config_key, else the label without seed), first-seen order."""
    groups: dict[Any, list[str]] = {}
    labels: dict[Any, str] = {}
    for rid in run_ids:
        ck = res.runs.at[rid, "config_key"] if "config_key" in res.runs.columns else None
        lab = run_label(res, rid)
        seed = res.runs.at[rid, "seed"]
        if not is_null(seed) and lab.endswith(f" s{int(seed)}"):
            lab = lab[: -len(f" s{int(seed)}")]
        key = (str(res.runs.at[rid, "scene"]), ck) if not is_null(ck) else lab
        groups.setdefault(key, []).append(rid)
        labels.setdefault(key, lab)
    return [(labels[k], v) for k, v in groups.items()]


def mean_shares(per_run: list[dict[int, dict[str, float]]]) -> tuple[list[int], dict[str, list[float]]]:
    """Mean share per term over the runs (seeds) at the steps that all of them logged; a term a run
    does not log counts as 0 for that run."""
    steps = sorted(set.intersection(*(set(r) for r in per_run))) if per_run else []
    terms = sorted({t for r in per_run for s in steps for t in r[s]})
    mean = {t: [sum(r[s].get(t, 0.0) for r in per_run) / len(per_run) for s in steps] for t in terms}
    return steps, mean


def plot_loss_shares(res: Results, study: Any, run_ids: list[str], path: Path) -> tuple[Path | None, list[str]]:
    """Stacked areas of the loss shares over steps, one panel per configuration (mean over its seeds)."""
    notes: list[str] = []
    panels = []
    without = 0
    for label, rids in _cells(res, run_ids):
        logs = [read_shares(str(res.runs.at[r, "run_dir"])) for r in rids]
        logs = [lg for lg in logs if lg]
        without += len(rids) - len(logs)
        if not logs:
            continue
        steps, mean = mean_shares(logs)
        if steps:
            panels.append((label, len(logs), steps, mean))
    if without:
        notes.append(f"Loss shares: {without} of {len(run_ids)} run(s) log no loss_share in train_log.jsonl "
                     "(left out of the loss-share plot).")
    if not panels:
        return None, notes
    if len(panels) > MAX_PANELS:
        notes.append(
            f"Loss shares: {len(panels) - MAX_PANELS} configuration(s) beyond the first {MAX_PANELS} not plotted."
        )
        panels = panels[:MAX_PANELS]
    terms = sorted({t for _, _, _, m in panels for t in m})
    cmap = plt.cm.tab10
    color = {t: cmap(i % 10) for i, t in enumerate(terms)}
    ncol = min(3, len(panels))
    nrow = math.ceil(len(panels) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(5.2 * ncol, 3.4 * nrow), squeeze=False)
    for ax, (label, n, steps, mean) in zip(axes.flat, panels):
        ts = [t for t in terms if t in mean]
        ax.stackplot(steps, [mean[t] for t in ts], labels=ts, colors=[color[t] for t in ts], alpha=0.85)
        ax.set_title(f"{label} (n={n})", fontsize=8)
        ax.set_xlabel("step")
        ax.set_ylabel("share of total loss")
        ax.set_ylim(0.0, max(1.0, max(sum(v) for v in zip(*mean.values()))))
        ax.grid(True, alpha=0.3)
    for ax in list(axes.flat)[len(panels):]:
        ax.axis("off")
    handles = [plt.Rectangle((0, 0), 1, 1, color=color[t]) for t in terms]
    axes[0][0].legend(handles, terms, loc="upper right", fontsize=7, title="weighted term", title_fontsize=7)
    name = "standalone / reconstruction runs" if study is None else f"study '{study}'"
    fig.suptitle(f"Share of each weighted loss term in the total loss — {name} (mean over seeds)", fontsize=11)
    return _save(fig, path), notes
