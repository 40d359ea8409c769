"""`gsbench verify --grids`: the draw takes one cell of each named grid in turn, and names a grid the store
lacks."""
from __future__ import annotations

from pathlib import Path

import pytest

from gsbench.errors import InputError
from gsbench.grids.store import Published
from gsbench.grids.verify import draw
from gsbench.numerics import NUMERICS_VERSION


def _cell(grid: str, i: int, version: int = NUMERICS_VERSION) -> Published:
    rec = {"grid": grid, "run_id": f"{grid[:4]}{i:012x}", "numerics_version": version,
           "cell": {"method": "gaussiands", "seed": i, "axes": {}}, "results": {"metrics": {}}, "provenance": {}}
    return Published(Path(f"{grid}/{i}.json"), rec)


def _store() -> list[Published]:
    cells = [_cell("dense-cpu", i) for i in range(40)] + [_cell("few-cpu", i) for i in range(5)]
    return cells + [_cell("real-cpu", i) for i in range(3)] + [_cell("real-cpu", 9, version=NUMERICS_VERSION - 1)]


def test_one_cell_from_each_named_grid_in_turn():
    for seed in range(5):
        got = draw(_store(), 3, seed, ["real-cpu", "few-cpu", "dense-cpu"])
        assert [c.grid for c in got] == ["real-cpu", "few-cpu", "dense-cpu"]   # a uniform draw would favour dense
        assert all(c.numerics_version == NUMERICS_VERSION for c in got)


def test_more_cells_than_grids_go_round_and_stop_when_a_grid_runs_out():
    got = draw(_store(), 10, 0, ["real-cpu", "few-cpu"])
    assert [c.grid for c in got].count("real-cpu") == 3 and len(got) == 8    # 3 current real cells, 5 few-view
    assert len({c.run_id for c in got}) == len(got)


def test_the_draw_is_seeded_and_plain_without_grids():
    assert draw(_store(), 4, 1, ["dense-cpu"]) == draw(_store(), 4, 1, ["dense-cpu"])
    assert len(draw(_store(), 4, 1)) == 4


def test_an_unknown_grid_is_named():
    with pytest.raises(InputError, match="no-such-cpu"):
        draw(_store(), 1, 0, ["dense-cpu", "no-such-cpu"])
