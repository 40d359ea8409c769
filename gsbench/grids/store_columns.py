"""A cell's per-view values as one compact column block (store format 3, gsbench.grids.store_format).

`results.per_view` ({metric: [value per view]}) was half of a published cell's file: about 390
numbers a cell, each written out in 17 or 18 characters, and over a third of the lists are copies of
another (a query mode's lists are the default mode's). The numbers themselves cannot be written shorter in
decimal without losing bits, so the block is stored as

    "per_view": {"$columns": "<base64 text>"}

where the base64 text is zlib-compressed bytes: one line of JSON, `[[metric, n], ...]` (sorted by
metric), a newline, then every value of those lists in that order as an 8-byte little-endian IEEE
double, null stored as NaN (a stored value is never NaN: the readers refuse it). The values are the
doubles' own bits, so every number reads back equal (==, -0.0 included), and zlib drops the copied
lists. A block with a value that is no float or null (an integer), or one that packs no shorter,
is kept as plain lists; readers take both.
"""
from __future__ import annotations

import base64
import binascii
import json
import math
import struct
import zlib
from pathlib import Path
from typing import Any

from gsbench.errors import InputError, shorten
from gsbench.store import MAX_JSON_BYTES, parse_json

COLUMNS_REF = "$columns"
_DOUBLE = 8


def is_columns(block: Any) -> bool:
    """Whether a stored per-view block is a column block."""
    return isinstance(block, dict) and set(block) == {COLUMNS_REF}


def _packable(per_view: Any) -> bool:
    return isinstance(per_view, dict) and bool(per_view) and all(
        isinstance(v, list) and all(x is None or isinstance(x, float) for x in v)
        for v in per_view.values())


def pack_columns(per_view: Any, plain_size: int) -> Any:
    """The block as stored: a column block when every value is a float or null and the block's text
    is shorter than `plain_size` (the plain lists' size), else the block unchanged. A non-finite
    float is stored as null, as the plain writer stores it."""
    if not _packable(per_view):
        return per_view
    names = sorted(per_view, key=str)
    head = json.dumps([[str(k), len(per_view[k])] for k in names], ensure_ascii=True, separators=(",", ":"))
    values = [x if x is not None and math.isfinite(x) else math.nan for k in names for x in per_view[k]]
    body = struct.pack(f"<{len(values)}d", *values)
    text = base64.b64encode(zlib.compress(head.encode("ascii") + b"\n" + body, 9)).decode("ascii")
    return {COLUMNS_REF: text} if len(text) + len(COLUMNS_REF) + 8 < plain_size else per_view


def _bad(path: Path, why: str) -> InputError:
    return InputError(f"{shorten(path)}: results.per_view is a column block that does not decode ({why}); "
                      "re-publish the cell (the store is written by gsbench publish, never by hand)")


def _inflate(text: Any, path: Path) -> bytes:
    if not isinstance(text, str) or not text.isascii():
        raise _bad(path, "not base64 text")
    try:
        raw = base64.b64decode(text.encode("ascii"), validate=True)
    except (binascii.Error, ValueError):
        raise _bad(path, "not base64 text") from None
    unzip = zlib.decompressobj()
    try:
        data = unzip.decompress(raw, MAX_JSON_BYTES)
    except zlib.error as e:
        raise _bad(path, f"zlib: {e}") from None
    if unzip.unconsumed_tail:
        raise _bad(path, f"more than {MAX_JSON_BYTES} bytes unpacked")
    if not unzip.eof or unzip.unused_data:
        raise _bad(path, "cut short, or bytes after its end")
    return data


def _head(head: bytes, path: Path) -> list[tuple[str, int]]:
    try:
        names = parse_json(head.decode("utf-8"), f"{shorten(path)}: results.per_view")
    except UnicodeDecodeError:
        names = None
    if not isinstance(names, list) or not all(
            isinstance(p, list) and len(p) == 2 and isinstance(p[0], str) and type(p[1]) is int and p[1] >= 0
            for p in names):
        raise _bad(path, "its first line is not a list of [metric, count]")
    if len({p[0] for p in names}) != len(names):
        raise _bad(path, "a metric named twice")
    return [(p[0], p[1]) for p in names]


def unpack_columns(block: dict, path: Path) -> dict:
    """The plain per-view block ({metric: [float or None, ...]}) of a column block; a block that does
    not decode is one InputError naming the file."""
    head, sep, body = _inflate(block[COLUMNS_REF], path).partition(b"\n")
    if not sep:
        raise _bad(path, "no line of metric names")
    names = _head(head, path)
    total = sum(n for _, n in names)
    if len(body) != total * _DOUBLE:
        raise _bad(path, f"{len(body)} bytes of values for {total} values")
    values = struct.unpack(f"<{total}d", body)
    out, at = {}, 0
    for name, n in names:
        out[name] = [None if math.isnan(v) else v for v in values[at:at + n]]
        at += n
    return out


__all__ = ["COLUMNS_REF", "is_columns", "pack_columns", "unpack_columns"]
