"""A finished run folder read back: `load_run(run_dir) -> (trained Method, resolved config, Scene)`.

Why here, in gsbench.evaluation and not gsbench.runs: the evaluation loads the run it scores, and the
training loop (gsbench.runs.training) scores with the evaluation's scorer. With load_run in
gsbench.runs the two packages imported each other; here the imports go one way, runs -> evaluation.
It needs only the method's own loader (Method.load), the
scene loader and the run folder's names (gsbench.rundir). A run is read only when its config.json
still gives its run id (`check_identity`).
"""
from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

from gsbench import rundir
from gsbench.config import get_dotted, run_config, run_id, set_dotted
from gsbench.datasets import load_scene
from gsbench.errors import InputError, shorten
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
    raw = read_json(run_dir / rundir.CONFIG)
    cfg = run_config(raw, run_dir / rundir.CONFIG)
    method = Method.load(run_dir / rundir.MODEL)
    if method.name != cfg["method"]:
        raise InputError(f"{run_dir / rundir.CONFIG}: names method {cfg['method']!r}, but the model in "
                         f"{rundir.MODEL} is {method.name!r} (the folder mixes two runs)")
    check_identity(raw, cfg, run_dir / rundir.CONFIG, rundir.read_optional(run_dir / rundir.TRAIN_SUMMARY))
    scene = load_scene(cfg["scene"]["path"])
    return method, cfg, scene


def _as_trained(cfg: dict) -> dict:
    """The config before the resolver switched losses off for the scene: each switch it recorded in
    `dropped` (a dotted key holding False) back on. The run id was computed from this config."""
    out = copy.deepcopy(cfg)
    for part in cfg.get("dropped") or {}:
        try:
            if get_dotted(out, str(part)) is False:
                set_dotted(out, str(part), True)
        except KeyError:
            continue
    return out


def check_identity(raw: Any, cfg: dict, path: Path, summary: Any = None) -> None:
    """The run's identity: config.json must be the config the run trained with. An edited seed or
    weight, or a config.json of another run, is refused in one line: the results would be reported
    under values the run was not trained with. `raw` is config.json as read, `cfg` the same in today's
    layout (gsbench.config), `summary` the run's train_summary.json.

    A run trained by this gsbench records the id of its config as written (after the method's resolver)
    in train_summary.json (`resolved_config_id`), and that id is computed again. An older run has only
    its run id, computed before the resolver: it is computed again from the config with the loss
    switches the resolver recorded in `dropped` turned back on (the only change built-in resolvers
    made then)."""
    recorded = cfg.get("run_id")
    fingerprint = (cfg.get("scene") or {}).get("fingerprint")
    if not isinstance(recorded, str) or not isinstance(fingerprint, str):
        raise InputError(f"{path}: no run_id or scene.fingerprint: not the config.json of a gsbench run "
                         "(the run's identity cannot be checked)")
    resolved = summary.get("resolved_config_id") if isinstance(summary, dict) else None
    if isinstance(resolved, str):
        now = run_id(cfg, fingerprint)
        if summary.get("run_id") == recorded and now == resolved:
            return
        raise _edited(path, recorded, f"the config it trained with has id {shorten(resolved, 40)}, this one {now}")
    for c in (c for c in (cfg, raw) if isinstance(c, dict)):
        for form in (c, _as_trained(c)):
            try:
                if run_id(form, fingerprint) == recorded:
                    return
            except (TypeError, ValueError, KeyError):
                continue
    raise _edited(path, recorded, f"computed again: {shorten(run_id(cfg, fingerprint), 40)}")


def _edited(path: Path, recorded: str, detail: str) -> InputError:
    """The one-line refusal of a config.json that is not the one its run trained with."""
    return InputError(f"{path}: the config does not give the run's id {shorten(recorded, 40)} ({detail}): it was "
                      "edited after training (e.g. seed or a loss weight) or belongs to another run; retrain with "
                      "the new values into a new folder")
