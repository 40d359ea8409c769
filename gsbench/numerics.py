"""NUMERICS_VERSION: which generation of gsbench's numbers a run belongs to.

Why a number of its own: a published cell (results/cpu, docs/publishing.md) is reused and trusted
across sessions and commits only while today's code would compute the same numbers for it. The run
id already changes with the config (a new default, another grid) and the scene, but not with the
code; the commit changes with every edit, numbers or not. So whoever changes what a run computes for
an unchanged config and scene bumps this version in that commit, and every published cell of an
older version is then stale (listed, never reused, never in the table).

Bump it for a change to the training, the render kernels, a loss, a prior's simulator, a metric,
the evaluation protocol, the data loaders or the synthetic scene generator that moves any number.
Do not bump it for a new config default or grid (the run ids change on their own), speed work that
keeps the bits, the reports or the docs. `gsbench verify results/cpu --cells 3` tells, on the CPU
family that published the cells, whether a change moved a number.

Every run records it (env.json and results.json `machine`, gsbench.environment.env_info).
"""
from __future__ import annotations

NUMERICS_VERSION = 1

# version -> what changed (one line each, newest last)
NUMERICS_HISTORY: dict[int, str] = {
    1: "the first recorded version (issue 38: the published results store)",
}
