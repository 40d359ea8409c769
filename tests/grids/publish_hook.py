"""Run `gsbench ARGV` with the file operations of the store's write wrapped (a test's subprocess:
tests/grids/test_store_publish_safety.py).

    python publish_hook.py MODE N MARKER gsbench-argv...

MODE pause: when the write begins (the store's lock held), write MARKER and wait for MARKER.go.
MODE kill: SIGKILL this process at the N-th file operation (os.replace, rename, link, unlink, and the
folders' exchange) of the write. MODE count: only count them. The count is written to MARKER.calls.
"""
from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

from gsbench.cli import main
from gsbench.grids import store_write

MODE, N, MARKER = sys.argv[1], int(sys.argv[2]), Path(sys.argv[3])
STATE = {"on": False, "calls": 0}


def _step() -> None:
    if STATE["on"]:
        STATE["calls"] += 1
        if MODE == "kill" and STATE["calls"] == N:
            os.kill(os.getpid(), signal.SIGKILL)


def _counted(real):
    def wrapped(*args, **kwargs):
        _step()
        return real(*args, **kwargs)
    return wrapped


for _name in ("replace", "rename", "link", "unlink"):
    setattr(os, _name, _counted(getattr(os, _name)))
_exchange = store_write.exchange


def _exchange_counted(a, b):
    _step()
    _exchange(a, b)
    _step()


store_write.exchange = _exchange_counted
_commit = store_write.StoreWriter.commit


def _commit_hooked(self, *args, **kwargs):
    STATE["on"] = True
    if MODE == "pause":
        MARKER.write_text("holding the lock")
        t0 = time.time()
        while not MARKER.with_suffix(".go").exists() and time.time() - t0 < 300:
            time.sleep(0.05)
    return _commit(self, *args, **kwargs)


store_write.StoreWriter.commit = _commit_hooked

if __name__ == "__main__":
    code = main(sys.argv[4:])
    MARKER.with_suffix(".calls").write_text(str(STATE["calls"]))
    sys.exit(code)
