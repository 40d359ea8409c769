"""Where a claim study's spread comes from: the shares of a metric's variance that the seed, the
study's setting (its grid row) and the rest explain, from a two-way analysis of variance without
replication on the complete setting x seed table.

Why on the claims page: a flat claims table is a finding to explain. When the seed explains nearly
all of a metric's variance and the settings almost none, the studied mechanism does not move that
metric here, and what does move it is what the seed draws: in gsbench the simulated priors' failures
(masks, features, depth noise) and the initialisation. A paired interval already removes the seed's
share; this table says how large that share was and how little was left for the settings.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from gsbench.methods.gaussiands import study_table
from gsbench.methods.gaussiands.study_table import Claim
from gsbench.reports.controls import scene_label
from gsbench.reports.data import Results
from gsbench.reports.display import metric_spec
from gsbench.reports.studies import _get, scene_protocols
from gsbench.reports.table import Cell, Column, Row, Table


@dataclass
class Shares:
    """Variance shares (fractions of the total sum of squares) and the two mean spreads."""
    seed: float
    setting: float
    rest: float
    sd_seeds: float     # mean over settings of the sample sd across seeds
    sd_settings: float  # mean over seeds of the sample sd across settings


def variance_shares(table: np.ndarray) -> Shares | None:
    """Shares of the total sum of squares of a settings x seeds table (rows = settings, columns =
    seeds, every cell finite): seed = columns, setting = rows, rest = the interaction left over.
    None when the table is smaller than 2 x 2 or has no variance at all."""
    a = np.asarray(table, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] < 2 or a.shape[1] < 2 or not np.all(np.isfinite(a)):
        return None
    centred = a - a.mean()
    total = float(np.sum(centred ** 2))
    if not total > 0.0:
        return None
    ss_setting = a.shape[1] * float(np.sum((a.mean(axis=1) - a.mean()) ** 2))
    ss_seed = a.shape[0] * float(np.sum((a.mean(axis=0) - a.mean()) ** 2))
    rest = max(total - ss_setting - ss_seed, 0.0)  # rounding can take it a hair below zero
    return Shares(ss_seed / total, ss_setting / total, rest / total,
                  float(np.mean(a.std(axis=1, ddof=1))), float(np.mean(a.std(axis=0, ddof=1))))


def _setting(res: Results, rid: str) -> tuple:
    """A run's setting: its method and its values on the study's axes."""
    return (_get(res, rid, "method"),) + tuple(str(_get(res, rid, c)) for c in res.axis_columns)


def setting_table(res: Results, ids: list[str], metric: str, scale: float) -> tuple[np.ndarray, int]:
    """The settings x seeds table of the settings that have a value on every seed any setting ran,
    and how many settings were left out for a missing seed (a failed run, or no such metric)."""
    groups: dict[tuple, list[str]] = {}
    for rid in ids:
        groups.setdefault(_setting(res, rid), []).append(rid)
    by_setting = [res.seed_values(rids, metric, scale) for rids in groups.values()]
    seeds = sorted({s for v in by_setting for s in v if isinstance(s, int)})
    rows = [[v[s] for s in seeds] for v in by_setting if all(s in v for s in seeds)]
    return np.array(rows, dtype=np.float64).reshape(len(rows), len(seeds)), len(by_setting) - len(rows)


def _study_metrics(claims: list[Claim]) -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    for c in claims:
        if (c.study, c.metric) not in out:
            out.append((c.study, c.metric))
    return out


def _row(res: Results, study: str, metric: str, scene: str, protocol: Any,
         kinds: dict[str, str] | None = None) -> Row | None:
    concrete = res.resolve(metric, protocol)
    if concrete is None:
        return None
    sp = metric_spec(concrete)
    table, left_out = setting_table(res, res.run_ids(study=study, scene=scene, protocol=protocol), concrete, sp.scale)
    sh = variance_shares(table)
    if sh is None:
        return None
    size = f"{table.shape[0]} x {table.shape[1]}" + (f" ({left_out} left out)" if left_out else "")
    d = sp.decimals
    return Row([study, sp.label, scene_label(scene, protocol, kinds)],
               [Cell(text=size), Cell(text=f"{sh.sd_seeds:.{d}f}"), Cell(text=f"{sh.sd_settings:.{d}f}"),
                Cell(text=f"{100 * sh.seed:.0f} %"), Cell(text=f"{100 * sh.setting:.0f} %"),
                Cell(text=f"{100 * sh.rest:.0f} %")])


def spread_table(res: Results, claims: list[Claim] | None = None, kinds: dict[str, str] | None = None) -> list[Table]:
    """One row per claim study, metric and scene with a complete table of at least 2 settings x 2 seeds
    (`kinds`: scene name -> synthetic / real, for the Scene column)."""
    rows = []
    for study, metric in _study_metrics(study_table.paper_claims() if claims is None else claims):
        ids = res.run_ids(study=study)
        for scene, protocol in scene_protocols(res, ids) if ids else []:
            row = _row(res, study, metric, scene, protocol, kinds)
            if row is not None:
                rows.append(row)
    if not rows:
        return []
    cols = [Column("size", "Settings x seeds", "Settings $\\times$ seeds"),
            Column("sd_seeds", "sd across seeds", "sd across seeds"),
            Column("sd_settings", "sd across settings", "sd across settings"),
            Column("seed", "Seed share", "Seed share"), Column("setting", "Setting share", "Setting share"),
            Column("rest", "Rest", "Rest")]
    cap = ("Where each claim study's spread comes from: the shares of the metric's variance explained by the seed, "
           "by the study's setting (its grid row) and by the rest (their interaction), from a two-way analysis of "
           "variance without replication on the settings that ran every seed; sd across seeds = the mean over "
           "settings of the sample sd across seeds, sd across settings = the mean over seeds of the sample sd "
           "across settings (display units). A seed share near 100 % with a setting share near 0 says the study's "
           "settings do not move the metric here; what the seed draws (the simulated priors' failures and the "
           "initialisation) does.")
    return [Table("claims_spread", "Where the spread comes from", cap, ["Study", "Metric", "Scene"], cols, rows,
                  section="claims")]
