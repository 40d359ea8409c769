"""Atomic file writes and the run-folder / results.json contract.

Every file gsbench writes goes through `write_json_atomic` / `write_bytes_atomic` /
`save_torch_atomic`: the content is written to a temporary file in the same folder, flushed,
fsync'ed and renamed over the target, so an interrupted process never leaves a half-written file.

Run folder (one per trained run, NerfBaselines-like, one JSON of results per run):
  config.json       fully resolved config (method, scene, seed, every hyper-parameter, dropped parts)
  env.json          versions, git sha, host, cpu count, torch threads
  status.json       {"state": "running"|"done"|"failed"|"nonfinite"|"interrupted", "message": str, ...}
  train_log.jsonl   one JSON object per line: {"step", "wall_s", "loss": {...}, "eval": {...}?}
  checkpoint.pt     GaussianField state + optimiser state + step (atomic)
  results.json      the schema, the metric names and the builders are in gsbench/results.py

Study names, the grid axis keys they vary, their labels and reference rows: the one studies table,
methods/gaussiands/study_table.py.
"""
from __future__ import annotations

import json
import logging
import math
import os
import stat
import sys
import tempfile
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np

from gsbench.errors import InputError

log = logging.getLogger(__name__)


def _json_default(o: Any):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return _clean_float(float(o))
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    try:
        import torch
        if isinstance(o, torch.Tensor):
            return o.detach().cpu().tolist()
    except ImportError:  # pragma: no cover
        pass
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def _clean_float(x: float):
    """NaN/inf are not JSON: they become None (a value that could not be computed)."""
    return x if math.isfinite(x) else None


def _clean(obj: Any) -> Any:
    if isinstance(obj, float):
        return _clean_float(obj)
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    return obj


def _umask() -> int:
    """This process's umask: read from /proc where it can be (os.umask can only be read by setting it,
    which other threads would see for a moment), else by setting and restoring it once."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def new_folder_mode() -> int:
    """The mode mkdir gives a new folder (0777 less the umask), for folders tempfile.mkdtemp makes
    (0700) that become a command's output."""
    return 0o777 & ~_umask()


def _new_file_mode(path: Path) -> int:
    """The mode a file written at `path` gets: the mode of the file it replaces, else what open()
    would give a new file (0666 less the umask: 0644 with the usual umask 022)."""
    try:
        st = os.stat(path)
        if stat.S_ISREG(st.st_mode):
            return stat.S_IMODE(st.st_mode)
    except OSError:
        pass
    return 0o666 & ~_umask()


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write `data` to `path` atomically (temp file in the same folder, fsync, rename). The file gets
    the mode of the one it replaces, or a new file's mode (umask respected), not mkstemp's 0600.

    An OSError that names no file (a write or fsync failing with EFBIG, ENOSPC, EIO) is given `path`,
    so the one-line error says which file could not be written."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            os.fchmod(f.fileno(), _new_file_mode(path))
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as e:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if isinstance(e, OSError) and e.filename is None:
            e.filename = str(path)
        raise


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: str | os.PathLike, obj: Any) -> None:
    """JSON with NaN/inf written as null, numpy and torch values converted."""
    text = json.dumps(_clean(obj), indent=2, default=_json_default, allow_nan=False)
    write_text_atomic(path, text + "\n")


# Budgets of every JSON file gsbench reads (run folders, labels, scene files may come from elsewhere):
# the largest real ones are a few MB and 6 levels deep; Python's parser and the code walking the result
# recurse once per level, so a deeper document would end in a RecursionError instead of a message.
MAX_JSON_BYTES = 64 * 1024 * 1024
MAX_JSON_DEPTH = 64
_NOT_MARK = bytes(b for b in range(256) if b not in b'[]{}"')    # all bytes but brackets and quotes


def json_depth(text: str) -> int:
    """How deep the brackets of a JSON text nest, counted without parsing (so without recursion):
    escaped backslashes and quotes go first, then everything but brackets and quotes, then what
    stood between quotes (brackets inside strings do not nest). A fraction of json.loads' time."""
    body = text.encode("utf-8", "replace")
    if b"\\" in body:
        body = body.replace(b"\\\\", b"").replace(b'\\"', b"")
    brackets = b"".join(body.translate(None, _NOT_MARK).split(b'"')[::2])
    if not brackets:
        return 0
    codes = np.frombuffer(brackets, dtype=np.uint8)
    steps = ((codes == ord("[")) | (codes == ord("{"))).astype(np.int32) * 2 - 1
    return int(np.cumsum(steps).max())


def check_json_budget(text: str, where: str) -> None:
    """Refuse a JSON text over MAX_JSON_BYTES or nested deeper than MAX_JSON_DEPTH, naming `where` and
    the limit (never the text)."""
    if len(text) > MAX_JSON_BYTES:
        raise InputError(f"{where}: refused: {len(text)} characters of JSON, more than the "
                         f"{MAX_JSON_BYTES // 2**20} MiB gsbench reads")
    if json_depth(text) > MAX_JSON_DEPTH:
        raise InputError(f"{where}: refused: JSON nested deeper than {MAX_JSON_DEPTH} levels")


def parse_json(text: str, where: str) -> Any:
    """The one JSON parser: json.loads within the budgets; a bad text is an InputError naming `where`."""
    check_json_budget(text, where)
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(f"{where}: corrupt or truncated JSON ({e.msg} at line {e.lineno})") from None
    except RecursionError:    # the depth check comes first; kept so that no parse ends in a traceback
        raise InputError(f"{where}: refused: JSON nested too deep") from None
    except ValueError:        # an integer of more digits than Python converts (sys.get_int_max_str_digits)
        raise InputError(f"{where}: refused: an integer of more than {sys.get_int_max_str_digits()} digits") from None


def read_text_bounded(path: Path, max_bytes: int, kind: str) -> str:
    """A UTF-8 text file, refused before reading when it is larger than `max_bytes` (the one bounded
    reader of JSON and YAML files). A missing file is FileNotFoundError naming it; anything else that
    stops the read is an InputError naming the file."""
    try:
        size = path.stat().st_size
        if size > max_bytes:
            raise InputError(f"{path}: refused: {size} bytes, more than the {max_bytes // 2**20} MiB "
                             f"of {kind} gsbench reads")
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: file not found") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: corrupt {kind} (not UTF-8 text)") from None
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror})") from None


def read_json(path: str | os.PathLike) -> Any:
    """Read JSON; a missing file is a FileNotFoundError, a truncated, corrupt, too large or too deeply
    nested one an InputError naming the file."""
    path = Path(path)
    return parse_json(read_text_bounded(path, MAX_JSON_BYTES, "JSON"), str(path))


def append_jsonl(path: str | os.PathLike, obj: Any) -> None:
    """Append one line; a torn last line (crash mid-write) is skipped by `read_jsonl`."""
    line = json.dumps(_clean(obj), default=_json_default, allow_nan=False)
    with open(path, "a", encoding="utf-8") as f:
        f.write(line + "\n")
        f.flush()
        os.fsync(f.fileno())


def read_jsonl(path: str | os.PathLike) -> list[dict]:
    """All complete lines of a JSONL file; an incomplete or corrupt line is skipped (a crash mid-write
    tears the last one), a line over the JSON budgets too, with a warning. A file over MAX_JSON_BYTES
    is an InputError naming it."""
    out = []
    path = Path(path)
    if not path.exists():
        return out
    for i, line in enumerate(read_text_bounded(path, MAX_JSON_BYTES, "JSON").splitlines(), 1):
        line = line.strip()
        if not line:
            continue
        try:
            check_json_budget(line, f"{path} line {i}")
        except InputError as e:
            log.warning("%s; line skipped", e)
            continue
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return out


_PLAIN = (str, int, float, bool, type(None))


def _check_plain(obj: Any, where: str = "") -> None:
    """Raise TypeError unless `obj` is tensors and plain values only (what `load_torch` accepts)."""
    import torch
    if type(obj) in _PLAIN or isinstance(obj, torch.Tensor):     # exact types: numpy.float64 is a float
        return
    if type(obj) in (dict, OrderedDict):          # state_dict() is an OrderedDict
        for k, v in obj.items():
            if type(k) not in _PLAIN:
                raise TypeError(f"key {k!r} at {where or '/'} is a {type(k).__name__}")
            _check_plain(v, f"{where}/{k}")
        return
    if type(obj) in (list, tuple):
        for i, v in enumerate(obj):
            _check_plain(v, f"{where}/{i}")
        return
    raise TypeError(f"{where or '/'} is a {type(obj).__module__}.{type(obj).__name__}, not a tensor or plain value")


def save_torch_atomic(path: str | os.PathLike, obj: Any) -> None:
    """Save tensors and plain values (dict, list, tuple, str, int, float, bool, None) atomically.

    Anything else is refused here, so every file gsbench writes loads with `load_torch`."""
    import io

    import torch
    _check_plain(obj)
    buf = io.BytesIO()
    torch.save(obj, buf)
    write_bytes_atomic(path, buf.getvalue())


def _refusal(e: Exception) -> str:
    """The object torch refused to build (e.g. "GLOBAL posix.system"), else the message's first line."""
    import re
    m = re.search(r"GLOBAL [\w.]+", str(e))
    if m:
        return f"it would call or build {m.group(0)[len('GLOBAL '):]}"
    lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
    return lines[0] if lines else type(e).__name__


def load_torch(path: str | os.PathLike) -> Any:
    """Load a checkpoint or model file as data: tensors and plain values only.

    Files in run folders may come from elsewhere; a pickle that would build any other object (and so
    could run code) is refused with an InputError naming the file, before anything in it runs. A
    truncated or corrupt file is an InputError naming the file too."""
    import pickle

    import torch
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: checkpoint not found")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        if "weights only" in str(e).lower() or "GLOBAL" in str(e):
            raise InputError(f"{path}: refused: holds Python objects other than tensors and plain values, "
                             f"which could run code ({_refusal(e)}); gsbench loads run files as data only") from None
        raise InputError(f"{path}: corrupt or truncated checkpoint (UnpicklingError: {_refusal(e)})") from None
    except Exception as e:  # torch raises several types for corrupt files
        raise InputError(f"{path}: corrupt or truncated checkpoint ({type(e).__name__}: {_refusal(e)})") from None
