"""The previews contract: the small pictures `gsbench eval` leaves in a run folder for the report.

Why a file contract: the report must show renders, depth and masks, but it sits above the
evaluation and may not load models or render. So the evaluation saves what it rendered for a few
labelled frames, with the numbers it scored on them, and the report only reads and places them.

Run folder:
  previews/previews.json      the manifest (below); written last, it is what makes the folder valid
  previews/<key>.npz          arrays of one frame (np.savez_compressed, read with allow_pickle=False)

Manifest keys: previews_version, run_id, method, scene, providers, backend, query_mode,
max_width (the cap on a preview's width), frames [...], removal [...], removal_reason, notes.
A frame: key, file, protocol, view, frame_set, scored_size [W, H] (where the metrics were
computed), size [W, H] (of the saved arrays), psnr, psnr_impl, depth_range [lo, hi],
semantic_reason (None when there are masks), metric_impl, queries [{query, iou, biou, localized,
reason}] in the order of the arrays' first axis.
Frame arrays: render, gt (uint8 H x W x 3), depth (float16 H x W), alpha (uint8, 0..255),
gt_depth (float16 H x W, 0 = none; shape (0, 0) when the scene has no GT depth), pred, gt_masks
(uint8 Q x H x W, 0/1). A removal entry: key, file, view, query, n_pruned,
residual, psnr_outside, impl, size; arrays before, after, gt_after (uint8 H x W x 3), object (uint8 H x W).

The whole folder is replaced at once (`write_previews`): built in a temporary sibling and
renamed, so a reader never sees pictures of two evaluations mixed; the folder gets the mode mkdir
would give it (the umask respected), not the temporary folder's 0700.
"""
from __future__ import annotations

import io
import logging
import os
import shutil
import tempfile
import zipfile
from pathlib import Path
from typing import Optional

import numpy as np

from gsbench import rundir
from gsbench.errors import InputError
from gsbench.store import new_folder_mode, read_json, write_bytes_atomic, write_json_atomic

log = logging.getLogger(__name__)
PREVIEWS_DIR = rundir.PREVIEWS
MANIFEST = "previews.json"
PREVIEWS_VERSION = 1
FRAME_ARRAYS = ("render", "gt", "depth", "alpha", "gt_depth", "pred", "gt_masks")
REMOVAL_ARRAYS = ("before", "after", "gt_after", "object")


def write_previews(run_dir: Path, manifest: dict, arrays: dict[str, dict[str, np.ndarray]]) -> Path:
    """Replace run_dir/previews with the manifest and one .npz per key of `arrays`."""
    run_dir = Path(run_dir)
    final = run_dir / PREVIEWS_DIR
    tmp = Path(tempfile.mkdtemp(prefix=f".{PREVIEWS_DIR}.", dir=run_dir))
    try:
        os.chmod(tmp, new_folder_mode())     # it becomes previews/: a folder's mode, not mkdtemp's 0700
        for key, arrs in arrays.items():
            buf = io.BytesIO()
            np.savez_compressed(buf, **arrs)
            write_bytes_atomic(tmp / f"{key}.npz", buf.getvalue())
        write_json_atomic(tmp / MANIFEST, {"previews_version": PREVIEWS_VERSION, **manifest})
        old = None
        if final.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{PREVIEWS_DIR}.old.", dir=run_dir))
            os.replace(final, old / PREVIEWS_DIR)
        os.replace(tmp, final)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return final


def remove_previews(run_dir: Path) -> None:
    """Delete the previews of an earlier evaluation (so none outlive the results they belong to)."""
    final = Path(run_dir) / PREVIEWS_DIR
    if final.exists():
        shutil.rmtree(final)


def read_manifest(run_dir: Path) -> Optional[dict]:
    """The run's previews manifest, None when the run has none; a bad one is an InputError naming it."""
    path = Path(run_dir) / PREVIEWS_DIR / MANIFEST
    if not path.exists():
        return None
    m = read_json(path)
    if not isinstance(m, dict) or m.get("previews_version") != PREVIEWS_VERSION:
        got = m.get("previews_version") if isinstance(m, dict) else type(m).__name__
        raise InputError(f"{path}: expected previews_version {PREVIEWS_VERSION}, got {got!r}")
    for k in ("frames", "removal"):
        if not isinstance(m.get(k), list):
            raise InputError(f"{path}: '{k}' must be a list")
    return m


def read_arrays(run_dir: Path, entry: dict, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The arrays of one manifest entry (data only: pickled objects are refused)."""
    path = Path(run_dir) / PREVIEWS_DIR / str(entry.get("file", ""))
    if path.parent != Path(run_dir) / PREVIEWS_DIR or path.suffix != ".npz":
        raise InputError(f"{path}: a preview file must be a .npz inside {PREVIEWS_DIR}/")
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [n for n in names if n not in z.files]
            if missing:
                raise InputError(f"{path}: missing arrays {', '.join(missing)}")
            return {n: z[n] for n in names}
    except FileNotFoundError:
        raise InputError(f"{path}: preview file not found (listed in {MANIFEST})") from None
    except (ValueError, OSError, zipfile.BadZipFile) as e:
        raise InputError(f"{path}: not a readable .npz of arrays ({e})") from None
