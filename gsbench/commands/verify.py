"""`gsbench verify STORE --cells K [--seed S] [--grids G ...]`: re-run K published cells, drawn at random
(seeded; from the named grids in turn with --grids),
and compare every metric with the published one (exact on the CPU family that published it; elsewhere
within the prediction interval of the setting's published seeds; timing metrics never). Exit 1 on any
failure (docs/publishing.md)."""
from __future__ import annotations

import argparse
from pathlib import Path

from gsbench.errors import InputError
from gsbench.grids.store import read_store
from gsbench.grids.verify import draw, format_check, verify
from gsbench.numerics import NUMERICS_VERSION


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("store", type=Path, metavar="STORE", help="the published results store, e.g. results/cpu")
    parser.add_argument("--cells", type=int, required=True, metavar="K", help="how many cells to re-run")
    parser.add_argument("--seed", type=int, default=0, help="the draw's seed (default 0)")
    parser.add_argument("--grids", nargs="+", default=(), metavar="GRID",
                        help="draw only from these grids, one from each in turn (e.g. one grid per regime: "
                             "--cells 3 --grids headline-cpu headline-fewview-cpu headline-real-cpu)")


def run(args: argparse.Namespace) -> int:
    if args.cells < 1:
        raise InputError(f"--cells: expected at least 1, got {args.cells}")
    cells = read_store(args.store)
    if not draw(cells, 1, args.seed):
        raise InputError(f"{args.store}: no published cell of numerics version {NUMERICS_VERSION} to verify")
    checks = verify(cells, args.cells, args.seed, args.grids)
    for c in checks:
        print(format_check(c))
    bad = [c for c in checks if not c.ok]
    print(f"gsbench verify: {len(checks)} cells re-run (seed {args.seed}), {len(bad)} failed "
          "(exact on the CPU family that published a cell: any mismatch; elsewhere: a metric outside the seed spread)")
    return 1 if bad else 0
