"""A finished run folder read back: `load_run(run_dir) -> (trained Method, resolved config, Scene)`.

Why here, in gsbench.evaluation and not gsbench.runs: the evaluation loads the run it scores, and the
training loop (gsbench.runs.training) scores with the evaluation's scorer. With load_run in
gsbench.runs the two packages imported each other; here the imports go one way, runs -> evaluation.
It needs only the method's own loader (Method.load), the
scene loader and the run folder's names (gsbench.rundir).
"""
from __future__ import annotations

from pathlib import Path

from gsbench import rundir
from gsbench.config import run_config
from gsbench.datasets import load_scene
from gsbench.errors import InputError
from gsbench.methods.base import Method
from gsbench.store import read_json


def load_run(run_dir: str | Path):
    """(trained Method, resolved config, Scene) of a finished run folder. Its config.json must name the
    method of its model.pt (the model file records its method): a folder mixing two runs is refused."""
    run_dir = Path(run_dir)
    st = rundir.read_status(run_dir)
    if st is None:
        raise FileNotFoundError(f"{run_dir / 'status.json'}: not a run folder (no status.json)")
    if st.get("state") != "done":
        raise InputError(f"{run_dir}: run is not finished (status {st.get('state')!r}: {st.get('message', '')})")
    cfg = run_config(read_json(run_dir / rundir.CONFIG), run_dir / rundir.CONFIG)
    method = Method.load(run_dir / rundir.MODEL)
    if method.name != cfg["method"]:
        raise InputError(f"{run_dir / rundir.CONFIG}: names method {cfg['method']!r}, but the model in "
                         f"{rundir.MODEL} is {method.name!r} (the folder mixes two runs)")
    scene = load_scene(cfg["scene"]["path"])
    return method, cfg, scene
