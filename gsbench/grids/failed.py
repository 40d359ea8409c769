"""results.json of a failed cell, so reports show "n/a (run failed)" instead of "no run"."""
from __future__ import annotations

from pathlib import Path

from gsbench import rundir
from gsbench.datasets import load_scene
from gsbench.environment import env_info
from gsbench.evaluation import resolve_protocols
from gsbench.results import failed_results
from gsbench.store import read_json, write_json_atomic


def write_failed_results(spec: dict, run_dir: Path, status: dict) -> dict:
    """results.json of a failed cell (schema and builder: gsbench.results): status "failed", every
    metric null with the error as its reason. Identity fields come from the run's config.json when
    training got that far (the resolved config), else from the cell's config."""
    cfg_path = run_dir / rundir.CONFIG
    config = spec.get("config") or {}
    try:
        if cfg_path.exists():
            read = read_json(cfg_path)
            config = read if isinstance(read, dict) else config   # null or a list: keep the cell's own
    except ValueError:
        pass
    scene_name, protocols = None, []
    try:   # name and protocols as evaluate_run would record them, so the failed cell shares their columns
        scene = load_scene(spec["scene_path"])
        scene_name = scene.name or Path(scene.path).name
        protocols, _ = resolve_protocols(scene, "auto")
    except Exception:  # the scene itself may be what failed; its folder name identifies it
        pass
    identity = {
        "run_id": run_dir.name, "method": config.get("method", spec.get("method")),
        "scene": scene_name or Path(str(spec.get("scene_path"))).name, "scene_path": str(spec.get("scene_path")),
        "seed": config.get("seed", spec.get("seed")), "study": config.get("study", spec.get("study")),
        "grid": config.get("grid") or {}, "config": config,
        "protocol": protocols[0] if protocols else None, "protocols": protocols,
        "dropped": config.get("dropped", {}),
    }
    reason = f"run failed (attempt {status.get('attempt')}): {status.get('error', 'unknown error')}"
    results = failed_results(identity=identity, reason=reason, machine=env_info(),
                             timings={"train_s": None, "eval_s": None, "cell_wall_s": status.get("wall_s")})
    write_json_atomic(run_dir / rundir.RESULTS, results)
    return results
