"""The file format of the published results store: pretty JSON records whose large, repeated parts
are kept once.

A record (one cell of the claims plan) repeats sub-objects that most cells share word for word: the
metric implementation names, the frame lists and splits of a scene, the training schedule, the
machine. Kept in every cell they were a third of the store. Store version 2 keeps each such part once,
as STORE/_shared/<hash>.json, and the record holds `{"$shared": "<hash>"}` in its place; the hash is
the first 16 hex digits of the SHA-256 of the part's file, so a hand edit of a shared part is caught
on reading (the file no longer has its name's hash). Every reader goes through `read_record`, which
gives the whole record, so nothing above this module sees the difference; a version-1 record (no
references) reads as it is. The numbers a claim is computed from (`results.metrics`, per-view
values) stay in the cell's own file, so a cell's diff shows them.
"""
from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any

from gsbench.errors import InputError
from gsbench.store import read_json, write_text_atomic

STORE_VERSION = 2
READABLE_VERSIONS = (1, 2)
SHARED_DIR = "_shared"
SHARED_REF = "$shared"
# (section, key) of the parts kept once: word for word the same in most cells (docs/publishing.md)
SHARED_PARTS = (("config", "eval"), ("config", "grouping"), ("config", "priors"), ("config", "train"),
                ("results", "frames"), ("results", "machine"), ("results", "metric_impl"),
                ("results", "skipped"), ("results", "split"))


def record_text(obj: Any) -> str:
    """A record as pretty JSON with sorted keys, lists of numbers on one line (small, readable diffs)."""
    return _pretty(obj, 0) + "\n"


def _pretty(obj: Any, level: int) -> str:
    pad, end = "  " * (level + 1), "  " * level
    if isinstance(obj, dict):
        if not obj:
            return "{}"
        items = [f"{pad}{json.dumps(str(k), ensure_ascii=False)}: {_pretty(obj[k], level + 1)}"
                 for k in sorted(obj, key=str)]
        return "{\n" + ",\n".join(items) + "\n" + end + "}"
    if isinstance(obj, (list, tuple)):
        if any(isinstance(v, (dict, list, tuple)) for v in obj):
            return "[\n" + ",\n".join(pad + _pretty(v, level + 1) for v in obj) + "\n" + end + "]"
        return "[" + ", ".join(_pretty(v, level + 1) for v in obj) + "]"
    if isinstance(obj, float) and not math.isfinite(obj):
        return "null"
    return json.dumps(obj, ensure_ascii=False)


def _hash(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def pack(rec: dict) -> tuple[dict, dict[str, str]]:
    """(the record with its shared parts replaced by references, {hash: the part's file text})."""
    out = {**rec, "store_version": STORE_VERSION}
    parts: dict[str, str] = {}
    for section, key in SHARED_PARTS:
        value = (out.get(section) or {}).get(key)
        if not isinstance(value, (dict, list)) or not value:
            continue
        text = record_text(value)
        h = _hash(text)
        parts[h] = text
        out[section] = {**out[section], key: {SHARED_REF: h}}
    return out, parts


def write_record(store: Path, path: Path, rec: dict) -> None:
    """Write a record in today's format: its shared parts first (each once), then the cell's file;
    every file atomically, so an interrupted write leaves no half record."""
    packed, parts = pack(rec)
    folder = Path(store) / SHARED_DIR
    for h, text in parts.items():
        part = folder / f"{h}.json"
        if not part.exists():
            write_text_atomic(part, text)
    write_text_atomic(path, record_text(packed))


def _shared_part(store: Path, h: Any, where: str, path: Path) -> Any:
    part = store / SHARED_DIR / f"{h}.json"
    if not isinstance(h, str) or not part.is_file():
        raise InputError(f"{path}: {where} refers to shared part {h!r}, which {part} does not hold")
    text = part.read_text(encoding="utf-8")
    if _hash(text) != h:
        raise InputError(f"{part}: its content no longer has the hash its name gives (edited by hand?); "
                         "re-publish the cells that use it")
    return json.loads(text)


def unpack(rec: Any, path: Path) -> Any:
    """A record as read from `path` (STORE/<grid>/<run_id>.json) with its shared parts put back."""
    if not isinstance(rec, dict) or "store_version" not in rec:
        return rec                      # not a record: the reader's shape check says so
    version = rec.get("store_version")
    if version not in READABLE_VERSIONS:
        raise InputError(f"{path}: store version {version!r}; this gsbench reads versions "
                         f"{', '.join(map(str, READABLE_VERSIONS))} (a newer gsbench wrote it?)")
    store = Path(path).parent.parent
    out = dict(rec)
    for section, key in SHARED_PARTS:
        sec = out.get(section)
        value = sec.get(key) if isinstance(sec, dict) else None
        if isinstance(value, dict) and set(value) == {SHARED_REF}:
            out[section] = {**sec, key: _shared_part(store, value[SHARED_REF], f"{section}.{key}", path)}
    return out


def read_record(path: Path) -> Any:
    """The whole record of one cell file (its shared parts put back)."""
    return unpack(read_json(path), Path(path))


def cell_files(store: Path) -> list[Path]:
    """The cell files of a store (STORE/<grid>/<run_id>.json), sorted; shared parts and hidden folders left out."""
    return [p for p in sorted(Path(store).glob("*/*.json"))
            if not p.parent.name.startswith(".") and p.parent.name != SHARED_DIR]


def _refs(raw: Any) -> set[str]:
    """The hashes of the shared parts a cell file, as stored, refers to."""
    out = set()
    for section, key in SHARED_PARTS:
        sec = raw.get(section) if isinstance(raw, dict) else None
        value = sec.get(key) if isinstance(sec, dict) else None
        if isinstance(value, dict) and set(value) == {SHARED_REF}:
            out.add(str(value[SHARED_REF]))
    return out


def remove_unused_parts(store: Path) -> list[Path]:
    """Delete the shared parts no cell file refers to any more (a replaced or upgraded cell's); the
    references are read from the files as stored, so nothing is unpacked or re-serialised."""
    folder = Path(store) / SHARED_DIR
    if not folder.is_dir():
        return []
    used: set[str] = set()
    for p in cell_files(store):
        used |= _refs(read_json(p))
    gone = sorted(p for p in folder.glob("*.json") if p.stem not in used)
    for p in gone:
        p.unlink()
    return gone


__all__ = ["STORE_VERSION", "SHARED_DIR", "SHARED_PARTS", "record_text", "pack", "write_record", "read_record",
           "unpack", "cell_files", "remove_unused_parts"]
