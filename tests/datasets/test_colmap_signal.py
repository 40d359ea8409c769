"""Importing pycolmap through gsbench keeps Python's SIGTERM handler: without it, glog's failure handler
prints a C stack trace and aborts a process stopped with SIGTERM (a `gsbench claims` parent)."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

pytest.importorskip("pycolmap")

CHILD = """
import signal, sys, time
if sys.argv[1] == "handler":
    signal.signal(signal.SIGTERM, lambda s, f: (print("python handler ran", flush=True), sys.exit(7)))
if sys.argv[2] == "gsbench":
    from gsbench.colmap_lib import import_pycolmap
    import_pycolmap()
else:
    import pycolmap
print("ready", flush=True)
time.sleep(60)
"""


def _stop(handler: str, how: str) -> tuple[int, str, str]:
    p = subprocess.Popen([sys.executable, "-c", CHILD, handler, how], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "ready"
    time.sleep(0.2)
    p.send_signal(signal.SIGTERM)
    out, err = p.communicate(timeout=60)
    return p.returncode, out, err


def test_the_plain_import_replaces_python_s_handler():
    """The fault this guards against, shown on the bare import (a pycolmap that stops doing it skips)."""
    rc, out, err = _stop("handler", "bare")
    if "python handler ran" in out:
        pytest.skip("this pycolmap keeps Python's SIGTERM handler on import")
    assert rc != 7 and "SIGTERM" in err


@pytest.mark.parametrize("handler", ["default", "handler"])
def test_import_pycolmap_keeps_the_handler_python_had(handler):
    rc, out, err = _stop(handler, "gsbench")
    assert "*** Aborted" not in err and "stack trace" not in err
    if handler == "handler":
        assert rc == 7 and "python handler ran" in out
    else:
        assert rc == -signal.SIGTERM
