"""The runs folder `ablate` and `claims` write: one writer at a time, and never a folder of someone else's.

A runs folder holds, at its top level, what gsbench puts there: run folders (a folder holding a
run-folder file: config.json, status.json, cell.json, cell_status.json, results.json or
writer.lock; an empty folder counts too), the shared `scenes/` and priors cache, grid manifests
`grid-NAME.json`, `collected.parquet|csv` (gsbench collect), `report/` (gsbench claims; the report
guards its own folder, gsbench.outdir), `.submitit/`, the writer lock, and what a killed writer
leaves (a report's lock or staging folder, the temporary file of an atomic write). Anything else is
foreign: the folder is refused with one line naming it, unless `force`, and then left alone (gsbench
writes only its own names). Run folders are not looked into: each has its own writer lock.
"""
from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Iterator

from gsbench import rundir
from gsbench.errors import InputError
from gsbench.grids.planning import CACHE_DIRNAME, SCENES_DIRNAME
from gsbench.outdir import foreign_message, lock_path, staging_prefix
from gsbench.runlock import RunLock

REPORT_DIRNAME = "report"
RUN_FILES = (rundir.CONFIG, rundir.STATUS, rundir.CELL, rundir.CELL_STATUS, rundir.RESULTS, rundir.LOCK)
_NAMES = {SCENES_DIRNAME, CACHE_DIRNAME, ".submitit", REPORT_DIRNAME, "collected.parquet", "collected.csv",
          rundir.LOCK, rundir.LOCK + ".takeover"}


def _is_gsbench_entry(p: Path) -> bool:
    name = p.name
    if name in _NAMES:
        return True
    report = p.parent / REPORT_DIRNAME
    if p.is_symlink():
        return False
    if p.is_dir():
        return name.startswith(staging_prefix(report)) or not any(p.iterdir()) or any(
            (p / f).exists() for f in RUN_FILES)
    hidden_leftover = name.startswith(".") and (name.endswith(".tmp") or name.startswith(f".{rundir.LOCK}."))
    return ((name.startswith("grid-") and name.endswith(".json")) or name == lock_path(report).name
            or hidden_leftover)


def foreign_entries(runs_dir: Path) -> list[str]:
    """Names at the top of `runs_dir` that gsbench did not put there, sorted."""
    runs_dir = Path(runs_dir)
    if not runs_dir.is_dir():
        return []
    return sorted(p.name for p in runs_dir.iterdir() if not _is_gsbench_entry(p))


@contextlib.contextmanager
def owned_runs_folder(runs_dir: Path, command: str, force: bool = False) -> Iterator[None]:
    """Hold RUNS_DIR's writer lock (a second ablate or claims into it fails at once, naming this one)
    and refuse a folder with foreign entries unless `force`."""
    with RunLock(runs_dir, command, what="runs folder"):
        foreign = foreign_entries(runs_dir)
        if foreign and not force:
            raise InputError(foreign_message(Path(runs_dir), foreign[0], command))
        yield
