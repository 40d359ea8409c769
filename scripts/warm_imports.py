"""Import every gsbench module once, so that Python caches the bytecode of gsbench and of the
libraries it imports (`make install` runs it with bytecode writing on).

Why: `make install` lets pip install with --no-compile. pip otherwise compiles every file of every
package it installs (about 11,000 for torch and the rest, 28 s on a 2-core machine), while gsbench
imports about 2,200 of them (5 s here). Without cached bytecode, a shell that sets
PYTHONDONTWRITEBYTECODE would compile them again in every process.
"""
from __future__ import annotations

import importlib
import pkgutil

# the folders pyproject.toml maps into gsbench (package-dir): not subfolders of gsbench/, so a walk
# of gsbench's path does not find them
MAPPED = ("gsbench.methods", "gsbench.datasets", "gsbench.metrics", "gsbench.reports")


def import_all() -> list[str]:
    """Import every module of the package; returns their names."""
    names = set()
    for top in ("gsbench", *MAPPED):
        pkg = importlib.import_module(top)
        names.add(top)
        names.update(m.name for m in pkgutil.walk_packages(pkg.__path__, top + "."))
    for name in sorted(names):
        importlib.import_module(name)
    return sorted(names)


def main() -> int:
    print(f"imported {len(import_all())} gsbench modules")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
