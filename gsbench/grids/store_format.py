"""The file format of the published results store: pretty JSON records whose large, repeated parts
are kept once, and whose per-view values are one compact column block.

A record (one cell of the claims plan) repeats sub-objects that most cells share word for word: the
metric implementation names, the frame lists and splits of a scene, the training schedule, the
machine. Kept in every cell they were a third of the store. Store version 2 keeps each such part once,
as STORE/_shared/<hash>.json, and the record holds `{"$shared": "<hash>"}` in its place; the hash is
the first 16 hex digits of the SHA-256 of the part's file, so a hand edit of a shared part is caught
on reading (the file no longer has its name's hash). Every reader goes through `read_record`, which
gives the whole record, so nothing above this module sees the difference; a version-1 record (no
references) reads as it is. The numbers a claim is computed from (`results.metrics`, per-view
values) stay in the cell's own file, so a cell's diff shows them.

Store version 3 keeps a few more parts once (the method's section, the scene, the semantic settings,
the budget, the providers, the resolution) and writes `results.per_view` as one column block: the
values as the doubles' own bits, zlib-compressed (gsbench.grids.store_columns), about a third of
their size as decimal text and exact by construction. `read_record` gives the same record for a
version-2 or version-3 file; versions 1 and 2 are still read.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import re
import stat
from pathlib import Path
from typing import Any

from gsbench.collect import check_results_version, number_problem
from gsbench.errors import InputError, shorten
from gsbench.grids.store_columns import is_columns, pack_columns, unpack_columns
from gsbench.store import MAX_JSON_BYTES, parse_json, read_json, read_text_bounded, write_text_atomic

STORE_VERSION = 3
READABLE_VERSIONS = (1, 2, 3)
SHARED_DIR = "_shared"
SHARED_REF = "$shared"
# (section, key) of the parts kept once: word for word the same in most cells (docs/publishing.md)
SHARED_PARTS = (("config", "eval"), ("config", "gaussiands"), ("config", "grouping"), ("config", "priors"),
                ("config", "scene"), ("config", "semantic"), ("config", "train"),
                ("results", "budget"), ("results", "frames"), ("results", "machine"), ("results", "metric_impl"),
                ("results", "providers"), ("results", "resolution"), ("results", "skipped"), ("results", "split"),
                ("train_summary", "providers"))
PART_NAME = re.compile(r"^[0-9a-f]{16}\.json$")      # the only names the store writes under _shared
# the sections of a record's results that hold numbers a reader computes with (checked on reading)
NUMBER_SECTIONS = ("metrics", "timings", "memory")


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
    """(the record with its shared parts replaced by references and its per-view values as a column
    block, {hash: the part's file text})."""
    out = {**rec, "store_version": STORE_VERSION}
    res = out.get("results")
    if isinstance(res, dict) and res.get("per_view"):
        per_view = res["per_view"]
        out["results"] = {**res, "per_view": pack_columns(per_view, len(_pretty(per_view, 2)))}
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
        if not os.path.lexists(part):
            write_text_atomic(part, text)
        elif not part.is_file() or part.is_symlink() or _read_part_text(part) != text:
            raise InputError(f"{shorten(part)}: a shared part with other content than its name's hash (edited "
                             "by hand?); move it away, then publish again")
    write_text_atomic(path, record_text(packed))


def _read_part_text(part: Path) -> str:
    return read_text_bounded(part, MAX_JSON_BYTES, "JSON")


def _shared_part(store: Path, h: Any, where: str, path: Path) -> Any:
    if not isinstance(h, str) or not PART_NAME.match(f"{h}.json"):
        raise InputError(f"{shorten(path)}: {where} refers to shared part {shorten(repr(h), 40)}, which is no "
                         "part name (16 hex digits)")
    part = store / SHARED_DIR / f"{h}.json"
    if not part.is_file():
        raise InputError(f"{shorten(path)}: {where} refers to shared part {h!r}, which {shorten(part)} does not hold")
    text = _read_part_text(part)
    if _hash(text) != h:
        raise InputError(f"{shorten(part)}: its content no longer has the hash its name gives (edited by hand?); "
                         "re-publish the cells that use it")
    return parse_json(text, shorten(part))


def unpack(rec: Any, path: Path) -> Any:
    """A record as read from `path` (STORE/<grid>/<run_id>.json) with its shared parts put back."""
    if not isinstance(rec, dict) or "store_version" not in rec:
        return rec                      # not a record: the reader's shape check says so
    version = rec.get("store_version")
    if isinstance(version, bool) or version not in READABLE_VERSIONS:
        raise InputError(f"{shorten(path)}: store version {shorten(repr(version), 40)}; this gsbench reads versions "
                         f"{', '.join(map(str, READABLE_VERSIONS))} (a newer gsbench wrote it?)")
    store = Path(path).parent.parent
    out = dict(rec)
    for section, key in SHARED_PARTS:
        sec = out.get(section)
        value = sec.get(key) if isinstance(sec, dict) else None
        if isinstance(value, dict) and set(value) == {SHARED_REF}:
            out[section] = {**sec, key: _shared_part(store, value[SHARED_REF], f"{section}.{key}", path)}
    res = out.get("results")
    if isinstance(res, dict) and is_columns(res.get("per_view")):
        out["results"] = {**res, "per_view": unpack_columns(res["per_view"], Path(path))}
    return out


def read_record(path: Path) -> Any:
    """The whole record of one cell file (its shared parts put back), its stored numbers checked."""
    rec = unpack(read_json(path), Path(path))
    check_numbers(rec, Path(path))
    return rec


def _check_number(value: Any, path: Path, where: str) -> None:
    why = number_problem(value)
    if why:
        raise InputError(f"{shorten(path)}: {shorten(where, 80)} must be a finite number or null, got {why}")


def check_numbers(rec: Any, path: Path) -> None:
    """Every number a reader computes with (results.metrics, .timings, .memory, .per_view; the results
    version) a finite int or float within float range, or null; else an InputError naming the file
    and the key. Text in timings and memory (e.g. how fps was synchronised) is left to the readers."""
    res = rec.get("results") if isinstance(rec, dict) else None
    if not isinstance(res, dict):
        return                                  # not a record: the reader's shape check says so
    check_results_version(res, path)
    for section in NUMBER_SECTIONS:
        block = res.get(section)
        if block is not None and not isinstance(block, dict):
            raise InputError(f"{shorten(path)}: results.{section} must be an object")
        for k, v in (block or {}).items():
            if section == "metrics" or not isinstance(v, (str, bool, dict, list)):
                _check_number(v, path, f"results.{section}.{k}")
    per_view = res.get("per_view")
    if per_view is not None and not isinstance(per_view, dict):
        raise InputError(f"{shorten(path)}: results.per_view must be an object")
    for k, values in (per_view or {}).items():
        if not isinstance(values, list):
            raise InputError(f"{shorten(path)}: results.per_view.{shorten(k, 80)} must be a list")
        for i, v in enumerate(values):
            _check_number(v, path, f"results.per_view.{k}[{i}]")


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


def refuse_link(path: Path) -> None:
    """A symbolic link where the store writes or deletes is refused: nothing is done through it."""
    if os.path.islink(path):
        raise InputError(f"{shorten(path)}: a symbolic link; the store is written and pruned only as plain files "
                         "and folders, never through a link: replace it by the folder or file itself")


def is_own_part(part: Path) -> bool:
    """A part the store wrote: its name 16 hex digits + .json, a regular file (not a link) whose
    content has its name's hash. Anything else under _shared (a user's notes) is never deleted."""
    if not PART_NAME.match(part.name):
        return False
    st = os.lstat(part)
    if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_JSON_BYTES:
        return False
    try:
        return _hash(_read_part_text(part)) == part.stem
    except InputError:
        return False


def remove_unused_parts(store: Path) -> list[Path]:
    """Delete the shared parts no cell file refers to any more (a replaced or upgraded cell's); the
    references are read from the files as stored, so nothing is unpacked or re-serialised. Only parts
    the store wrote are deleted (`is_own_part`); a _shared that is a symbolic link, or a link named
    like a part, is refused (InputError) before anything is deleted."""
    folder = Path(store) / SHARED_DIR
    refuse_link(folder)
    if not folder.is_dir():
        return []
    used: set[str] = set()
    for p in cell_files(store):
        used |= _refs(read_json(p))
    with os.scandir(folder) as it:
        names = sorted(en.name for en in it)
    for name in names:
        if PART_NAME.match(name):
            refuse_link(folder / name)
    gone = [folder / n for n in names if n[:-len(".json")] not in used and is_own_part(folder / n)]
    for p in gone:
        p.unlink()
    return gone


__all__ = ["STORE_VERSION", "SHARED_DIR", "SHARED_PARTS", "PART_NAME", "record_text", "pack", "write_record",
           "read_record", "check_numbers", "unpack", "cell_files", "refuse_link", "is_own_part", "remove_unused_parts"]
