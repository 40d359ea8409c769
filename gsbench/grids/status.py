"""Status of a grid's cells as rows and as a plain-text table (`gsbench ablate --status`)."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

from gsbench.grids.grid_file import Grid, SceneSpec
from gsbench.grids.liveness import CELL_FILE, cell_state, read_cell_status
from gsbench.grids.planning import PlannedCell, plan
from gsbench.store import read_json


def status_rows(runs_dir: Path, grid: Optional[Grid] = None) -> list[dict]:
    """One row per cell: from the grid's plan when given (cells never started are pending), else from
    every cell folder found under RUNS_DIR."""
    runs_dir = Path(runs_dir)
    rows = []
    if grid is not None:
        return planned_rows(plan(grid, runs_dir, create_scenes=False))
    for cj in sorted(runs_dir.glob(f"*/{CELL_FILE}")):
        try:
            spec = read_json(cj)
        except ValueError:
            continue
        scene = spec.get("scene", {})
        label = SceneSpec(**scene).label if scene else ""
        rows.append(_row(cj.parent.name, cj.parent, spec.get("method", ""), label, spec.get("seed"),
                         spec.get("axes", {})))
    return rows


def planned_rows(planned: list[PlannedCell]) -> list[dict]:
    """Status rows of planned cells (cells never started are pending)."""
    return [_row(pc.run_id, pc.run_dir, pc.cell.method, pc.cell.scene.label, pc.cell.seed, pc.config.get("grid", {}))
            for pc in planned]


def _row(run_id, run_dir, method, scene, seed, axes) -> dict:
    state = cell_state(run_dir) if run_dir is not None and Path(run_dir).exists() else "pending"
    st = read_cell_status(run_dir) if run_dir is not None else {}
    return {"run_id": run_id or "-", "state": state, "method": method, "scene": scene, "seed": seed,
            "axes": ", ".join(f"{k}={v}" for k, v in axes.items()), "wall_s": st.get("wall_s"),
            "attempt": st.get("attempt", 0), "error": st.get("error", "") if state == "failed" else ""}


def format_status(rows: list[dict]) -> str:
    """A plain-text table plus counts."""
    cols = ["state", "run_id", "method", "scene", "seed", "attempt", "wall_s", "axes", "error"]
    table = [[_fmt(r.get(c)) for c in cols] for r in rows]
    widths = [max([len(c)] + [len(t[i]) for t in table]) for i, c in enumerate(cols)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(cols, widths)).rstrip()]
    for t in table:
        lines.append("  ".join(v.ljust(w) for v, w in zip(t, widths)).rstrip())
    counts: dict[str, int] = {}
    for r in rows:
        counts[r["state"]] = counts.get(r["state"], 0) + 1
    lines.append(f"{len(rows)} cells: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    return "\n".join(lines)


def _fmt(v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.1f}"
    s = str(v)
    return s if len(s) <= 80 else s[:77] + "..."
