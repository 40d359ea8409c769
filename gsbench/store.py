"""Atomic file writes and the run-folder / results.json contract.

Every file gsbench writes goes through `write_json_atomic` / `write_bytes_atomic` /
`save_torch_atomic`: the content is written to a temporary file in the same folder, flushed,
fsync'ed and renamed over the target, so an interrupted process never leaves a half-written file.

Run folder (one per trained run, NerfBaselines-like, one JSON of results per run):
  config.json       fully resolved config (method, scene, seed, every hyper-parameter, dropped parts)
  env.json          versions, git sha, host, cpu count, torch threads
  status.json       {"state": "running"|"done"|"failed"|"nonfinite", "message": str, "step": int, ...}
  train_log.jsonl   one JSON object per line: {"step", "wall_s", "loss": {...}, "eval": {...}?}
  checkpoint.pt     GaussianField state + optimiser state + step (atomic)
  results.json      the schema, the metric names and the builders are in gsbench/results.py

Study names, the grid axis keys they vary, their labels and reference rows: the one studies table,
gsbench/studies.py.
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np

from gsbench.errors import InputError


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


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write `data` to `path` atomically (temp file in the same folder, fsync, rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: str | os.PathLike, obj: Any) -> None:
    """JSON with NaN/inf written as null, numpy and torch values converted."""
    text = json.dumps(_clean(obj), indent=2, default=_json_default, allow_nan=False)
    write_text_atomic(path, text + "\n")


def read_json(path: str | os.PathLike) -> Any:
    """Read JSON; a missing, truncated or corrupt file is an InputError naming the file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: file not found") from None
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror})") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: corrupt or truncated JSON ({e.msg} at line {e.lineno})") from None


def append_jsonl(path: str | os.PathLike, obj: Any) -> None:
    """Append one line; a torn last line (crash mid-write) is skipped by `read_jsonl`."""
    line = json.dumps(_clean(obj), default=_json_default, allow_nan=False)
    with open(path, "a", encoding="utf-8") as f:
        f.write(line + "\n")
        f.flush()
        os.fsync(f.fileno())


def read_jsonl(path: str | os.PathLike) -> list[dict]:
    """All complete lines of a JSONL file; an incomplete trailing line is ignored."""
    out = []
    path = Path(path)
    if not path.exists():
        return out
    for line in path.read_text(encoding="utf-8").splitlines():
        line = line.strip()
        if not line:
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
