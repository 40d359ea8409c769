"""The run folder: the name of every file in it, and the readers beside the writers of the small ones.

One home for the layout, so a writer and its readers cannot disagree on a name:

    RUN/config.json          the resolved config (gsbench.runs)
    RUN/env.json             the machine and software that trained it
    RUN/status.json          running | done | failed | nonfinite | interrupted (Ctrl-C, SIGTERM), with the message
    RUN/checkpoint.pt        the last optimisation state (gsbench.runs.training)
    RUN/train_log.jsonl      one line per log / eval step (gsbench.runs.training)
    RUN/train_summary.json   training time, peaks, the method's info
    RUN/model.pt             the trained method (Method.save / Method.load)
    RUN/results.json         the evaluation (gsbench.results schema)
    RUN/previews/            small arrays for the report's pictures (gsbench.preview_files)
    RUN/cell.json            a grid cell's spec, RUN/cell_status.json its heartbeat (gsbench.grids)
    RUN/writer.lock          held by the one command writing the folder (gsbench.runlock)
    <runs>/.gsbench_cache/   the priors cache a folder of runs shares (priors.cache_dir: null)
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Optional

from gsbench.store import read_json, write_json_atomic

CONFIG = "config.json"
ENV = "env.json"
STATUS = "status.json"
CHECKPOINT = "checkpoint.pt"
TRAIN_LOG = "train_log.jsonl"
TRAIN_SUMMARY = "train_summary.json"
MODEL = "model.pt"
RESULTS = "results.json"
PREVIEWS = "previews"
CELL = "cell.json"
CELL_STATUS = "cell_status.json"
LOCK = "writer.lock"
CACHE_DIRNAME = ".gsbench_cache"


def write_status(run_dir: Path, state: str, message: str = "", **extra: Any) -> None:
    """status.json: the run's state and message, written atomically."""
    write_json_atomic(Path(run_dir) / STATUS, {"state": state, "message": message, "time": time.time(), **extra})


def read_status(run_dir: Path) -> Optional[dict]:
    """status.json as written by write_status, or None when the run has none yet."""
    p = Path(run_dir) / STATUS
    return read_json(p) if p.exists() else None


def read_optional(path: Path) -> dict:
    """A small JSON file of a run folder, or {} when it is absent (e.g. train_summary.json before the end)."""
    return read_json(path) if Path(path).exists() else {}


__all__ = ["CONFIG", "ENV", "STATUS", "CHECKPOINT", "TRAIN_LOG", "TRAIN_SUMMARY", "MODEL", "RESULTS", "PREVIEWS",
           "CELL", "CELL_STATUS", "LOCK", "CACHE_DIRNAME", "write_status", "read_status", "read_optional"]
