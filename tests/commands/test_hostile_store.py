"""The hostile:store battery (gsbench/commands/hostile/store.py) as tests: each case runs the real
command line on a copy of a tiny published store and passes (one line naming the file, no traceback,
the user's files kept)."""
from __future__ import annotations

import pytest

from gsbench.commands.hostile import run_hostile
from gsbench.commands.hostile.store import CASES


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_hostile_store_case(case):
    res = run_hostile(case)
    assert res.passed, res.note
