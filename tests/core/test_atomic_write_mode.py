"""Atomically written files get the mode a new file gets (0666 less the umask), or keep the mode of
the file they replace; never tempfile.mkstemp's 0600."""
from __future__ import annotations

import os
import stat

import pytest

from gsbench.store import write_bytes_atomic, write_json_atomic


def _mode(p) -> int:
    return stat.S_IMODE(os.stat(p).st_mode)


@pytest.mark.parametrize("mask", [0o022, 0o002, 0o077])
def test_a_new_file_respects_the_umask(tmp_path, mask):
    old = os.umask(mask)
    try:
        write_json_atomic(tmp_path / "a.json", {"x": 1})
    finally:
        os.umask(old)
    assert _mode(tmp_path / "a.json") == {0o022: 0o644, 0o002: 0o664, 0o077: 0o600}[mask]


def test_a_replaced_file_keeps_its_mode(tmp_path):
    p = tmp_path / "b.bin"
    p.write_bytes(b"old")
    os.chmod(p, 0o640)
    write_bytes_atomic(p, b"new")
    assert p.read_bytes() == b"new" and _mode(p) == 0o640
    assert not [q.name for q in tmp_path.iterdir() if q.name.endswith(".tmp")]
