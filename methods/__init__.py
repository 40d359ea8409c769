"""gsbench.methods: the Method protocol (base.py) and the methods behind it.

    get_method(name) -> Method class        # name: any of METHODS

Which methods exist is not listed here: each method registers through its spec module beside it
(`methods/<name>_spec.py`, or `spec.py` in a method's own folder), and the ground-floor table
gsbench/method_table.py discovers them (the built-in specs, then the `gsbench.methods` entry points
of installed plugins); METHODS reads the registered names. Importing this package does not import
torch: `Method` and the method classes load on first use.
"""
from __future__ import annotations

from typing import Any

from gsbench.method_table import METHODS


def __getattr__(name: str) -> Any:
    if name == "Method":
        from gsbench.methods.base import Method  # lazy: start-up (no trainer for a listing)
        return Method
    if name == "get_method":
        from gsbench.methods.registry import get_method  # lazy: start-up (a spec module loads this package)
        return get_method
    raise AttributeError(f"module 'gsbench.methods' has no attribute {name!r}")


__all__ = ["Method", "get_method", "METHODS"]
