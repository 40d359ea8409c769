"""On-disk cache of computed priors, keyed by a content hash.

key = sha256 of a canonical JSON of {part, provider id, version, parameters, input content}
(the caller puts everything the result depends on into it: scene fingerprint, view ids, image
size, order, seeds, ...). An entry is a folder ``cache_dir/<part>/<key>/`` holding
``arrays.npz`` and ``meta.json``; it is written into a temporary folder next to it and renamed
into place, so a crash never leaves a half-written entry and concurrent writers do not clash
(the first rename wins; the loser's temp folder is removed).
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from gsbench.datasets import scene_fingerprint
from gsbench.store import read_json, write_json_atomic

# 2: GT masks, classes and depth reach the priors' size by PIL-NEAREST centre sampling (gsbench.resize)
CACHE_VERSION = 2


def _canonical(obj: Any) -> Any:
    if isinstance(obj, Mapping):
        return {str(k): _canonical(v) for k, v in sorted(obj.items(), key=lambda kv: str(kv[0]))}
    if isinstance(obj, (list, tuple)):
        return [_canonical(v) for v in obj]
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, Path):
        return str(obj)
    return obj


def cache_key(part: str, provider: str | None, version: int, params: Mapping, content: Mapping) -> str:
    """sha256 hex of everything a cached result depends on."""
    blob = json.dumps(_canonical({"cache_version": CACHE_VERSION, "part": part, "provider": provider,
                                  "version": version, "params": params, "content": content}),
                      sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(blob.encode("utf-8")).hexdigest()


def scene_content_hash(scene) -> str:
    """The scene's content hash: `gsbench.datasets.scene_fingerprint` when the scene has a folder,
    else a hash of the image files' bytes, the cameras, and the GT files' presence (a fallback that
    still changes whenever an image or a camera does)."""
    if scene.path and Path(scene.path).exists():
        return "fp:" + str(scene_fingerprint(scene.path))
    h = hashlib.sha256()
    for cam in scene.cameras:
        h.update(json.dumps(cam.to_dict(), sort_keys=True).encode())
    for p in scene.image_paths:
        try:
            h.update(Path(p).read_bytes())
        except OSError:
            h.update(f"missing:{p}".encode())
    if not scene.image_paths:  # an in-memory scene: hash the decoded images
        for i in range(len(scene.cameras)):
            h.update(np.ascontiguousarray(np.asarray(scene.image(i), dtype=np.float32)).tobytes())
    h.update(json.dumps(scene.parts(), sort_keys=True).encode())
    return "img:" + h.hexdigest()


class PriorCache:
    """Folder-per-entry cache under `root` (None = disabled: every lookup misses, nothing is written)."""

    def __init__(self, root: str | os.PathLike | None):
        self.root = Path(root) if root is not None else None

    def entry(self, part: str, key: str) -> Path | None:
        return None if self.root is None else self.root / part / key

    def load(self, part: str, key: str) -> tuple[dict[str, np.ndarray], dict] | None:
        """(arrays, meta) of a complete entry, or None. A corrupt entry is removed and missed."""
        d = self.entry(part, key)
        if d is None or not (d / "meta.json").is_file() or not (d / "arrays.npz").is_file():
            return None
        try:
            meta = read_json(d / "meta.json")
            with np.load(d / "arrays.npz", allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except (ValueError, OSError, EOFError):
            shutil.rmtree(d, ignore_errors=True)
            return None
        return arrays, meta

    def save(self, part: str, key: str, arrays: Mapping[str, np.ndarray], meta: Mapping) -> Path | None:
        """Write an entry atomically (temp folder + rename); returns its folder."""
        d = self.entry(part, key)
        if d is None:
            return None
        d.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{key[:16]}.", dir=d.parent))
        try:
            with open(tmp / "arrays.npz", "wb") as f:
                np.savez_compressed(f, **{k: np.asarray(v) for k, v in arrays.items()})
                f.flush()
                os.fsync(f.fileno())
            write_json_atomic(tmp / "meta.json", dict(meta))
            try:
                os.rename(tmp, d)
            except OSError:
                if not (d / "meta.json").is_file():   # not a lost race: a real error
                    raise
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)
        return d
