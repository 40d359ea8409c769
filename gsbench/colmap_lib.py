"""pycolmap, imported with Python's SIGTERM handler kept.

Why: importing pycolmap installs glog's failure-signal handler, which on SIGTERM prints a C stack
trace and aborts, in place of whatever the process had: a `gsbench claims` parent that imported it
(the capture's sparse points, its sfm depth prior) dumped a trace when stopped with SIGTERM, and a
handler installed before the import (a run's checkpoint-on-SIGTERM) would be replaced. Every import
of pycolmap in gsbench goes through `import_pycolmap`, which puts back the handler Python had.
"""
from __future__ import annotations

import logging
import signal
import sys
import threading
from types import ModuleType

log = logging.getLogger(__name__)


def import_pycolmap() -> ModuleType:
    """The pycolmap module; on its first import from the main thread, SIGTERM's handler is the one
    Python had before (elsewhere signal handlers cannot be set, and glog's stays: logged)."""
    if "pycolmap" in sys.modules:
        return sys.modules["pycolmap"]
    before = signal.getsignal(signal.SIGTERM)
    import pycolmap

    if before is None:              # a handler not set from Python: nothing to put back
        return pycolmap
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, before)
    else:
        log.debug("pycolmap imported off the main thread: glog's SIGTERM handler stays")
    return pycolmap
