"""Liveness of a cell: its cell_status.json, the zombie-aware pid check, the heartbeat thread.

State pending|running|done|failed, pid, host, heartbeat (unix seconds), attempt count, error and
traceback. `stale` = marked running but its process is gone (same host) or its heartbeat is old.
"""
from __future__ import annotations

import socket
import time
from pathlib import Path
from typing import Optional

from gsbench import rundir
from gsbench.runlock import pid_alive
from gsbench.store import read_json

CELL_FILE = rundir.CELL
CELL_STATUS_FILE = rundir.CELL_STATUS
HEARTBEAT_S = 10.0
STALE_AFTER_S = 120.0


def read_cell_status(run_dir: Path) -> dict:
    p = Path(run_dir) / CELL_STATUS_FILE
    if not p.exists():
        return {"state": "pending"}
    try:
        return read_json(p)
    except ValueError:
        return {"state": "pending", "note": "unreadable cell_status.json"}


def cell_state(run_dir: Optional[Path], now: Optional[float] = None) -> str:
    """pending | running | stale | done | failed. `stale` = marked running but its process is gone
    (same host, pid dead) or its heartbeat is older than STALE_AFTER_S."""
    if run_dir is None:
        return "pending"
    st = read_cell_status(run_dir)
    state = st.get("state", "pending")
    if state == "done":
        return "done" if results_finished(run_dir) else "stale"
    if state == "running":
        now = time.time() if now is None else now
        if st.get("host") == socket.gethostname() and st.get("pid") and not pid_alive(int(st["pid"])):
            return "stale"
        if now - float(st.get("heartbeat", 0)) > STALE_AFTER_S:
            return "stale"
        return "running"
    return state if state in ("failed", "pending") else "pending"


def results_finished(run_dir: Path) -> bool:
    """results.json exists, is readable and is not a failure record (status "failed")."""
    p = Path(run_dir) / rundir.RESULTS
    if not p.exists():
        return False
    try:
        res = read_json(p)
    except ValueError:
        return False
    return isinstance(res, dict) and res.get("status") != "failed"


# Metrics a failed cell records as null (gsbench.store METRIC NAMES), so every table has its row.
