"""The one check every real provider makes before importing its library: the local weights exist.

Providers never download; a missing path is a one-line InputError naming the flag and the file.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional

from gsbench.errors import InputError


def require_weights(flag: str, path: Optional[str], what: str, provider_flag: str, folder: bool = False) -> Path:
    """`path` (given by `--set flag=...`) as a Path; an error naming flag and path when it is unset
    or not an existing file (`folder=True`: folder)."""
    need = f"({what} weights are needed for --set {provider_flag})"
    if not path:
        raise InputError(f"{flag}: not set {need}")
    p = Path(path)
    if not (p.is_dir() if folder else p.is_file()):
        raise InputError(f"{flag}: {path} not found {need}")
    return p
