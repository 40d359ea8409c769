"""The plan of `gsbench claims` as grids: every grid the paper-claims table and its positive controls
read (each study's `claims_grids` in methods/gaussiands/study_table.py, the one home of studies, claims,
controls and regimes), and the --quick variant of the same plan (tiny scale, two seeds) for CI and smoke
checks.

Why here: the claims command runs these grids with the ordinary grid machinery (run_grid, the
executors, resume), so what this module adds to the study table is loading the grids and, for --quick,
the overrides that shrink every cell.
"""
from __future__ import annotations

from dataclasses import replace

from gsbench.grids.grid_file import Grid, SceneSpec, load_grid
from gsbench.methods.gaussiands import study_table
from gsbench.methods.gaussiands.study_table import REGIMES, DeclaredRegime, Regime  # noqa: F401  (the plan's regimes)

# the grids of the paper-claims table, then the positive controls, as the study table declares them
# (methods/gaussiands/study_table.py); plan_grids reads the table again when it is called
CLAIM_GRIDS: tuple[str, ...] = study_table.claim_grids()
CONTROL_GRIDS: tuple[str, ...] = study_table.control_grids()


def plan_names() -> tuple[str, ...]:
    """The grids of the claims plan in running order: each study's claims_grids, paper studies then controls."""
    return study_table.claim_grids() + study_table.control_grids()


QUICK_SEEDS = [0, 1]
QUICK_RESOLUTION = [48, 36]   # synthetic scenes are generated this small under --quick
QUICK_VIEWS = 10              # views of a synthetic scene that does not fix its own count
QUICK_SET = {
    "train.iterations": 20,
    "train.max_width": 48,
    "train.eval_every": 1000,
    "train.checkpoint_every": 1000,
    "train.log_every": 10,
    "semantic.autoencoder.epochs": 5,
    "eval.fps_warmup": 0,
    "eval.fps_repeats": 1,
    "eval.previews": 0,       # the pictures are a quarter of a quick cell's evaluation and no claim reads them
}


def plan_grids(quick: bool = False, names: tuple[str, ...] | None = None) -> list[Grid]:
    """The grids the claims need, in running order; with `quick`, each shrunk to tiny scale and
    two seeds (the same cells otherwise, so the quick run exercises every study and control)."""
    out = []
    for name in names if names is not None else plan_names():
        if not quick:
            out.append(load_grid(name))
            continue
        g = load_grid(name, extra_set=dict(QUICK_SET))
        g.seeds = [s for s in g.seeds if s in QUICK_SEEDS] or QUICK_SEEDS
        g.later_seeds = [s for s in g.later_seeds if s in g.seeds]
        g.scenes = [_quick_scene(s) for s in g.scenes]
        out.append(g)
    return out


def _quick_scene(s: SceneSpec) -> SceneSpec:
    """A synthetic scene at QUICK_RESOLUTION (its view count kept when the grid sets one); a scene
    folder is kept as it is."""
    if not s.preset:
        return s
    return replace(s, resolution=list(QUICK_RESOLUTION), views=s.views or QUICK_VIEWS)
