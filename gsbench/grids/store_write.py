"""Writing the published store: one writer at a time, every check before any write, and all of it or none.

    with StoreWriter(store, "gsbench publish") as w:
        cells = read_store(store)                  # read under the lock: nothing changes it meanwhile
        ...                                        # decide; refuse here, and nothing was written
        w.commit([record, ...], [(grid, run_id), ...])

- **One writer.** `publish`, `publish --upgrade` and their prune hold a lock file beside the store
  (`.NAME.writer.lock`, gsbench.runlock) from the first read to the last write; a second writer fails
  at once with one line naming the holder.
- **No link is followed.** A symbolic link anywhere in the store (a `_shared` that points elsewhere,
  a grid folder, a part) is refused before anything is written: the store is plain files and folders.
- **All or none.** `commit` builds the new store beside the old one (`.NAME.publish-<pid>-<random>`):
  every file of the store hard-linked in (a copy where links are not possible), the new cells and
  parts written as new files (never into a linked one, so the store's own files are untouched), the
  removed cells unlinked, the unused parts pruned (store_format.remove_unused_parts). Then one rename
  exchanges the two folders (gsbench.outdir.exchange) and the old one is deleted, only the files seen
  at the start. A kill before the exchange leaves the old store, after it the new one; either way the
  scratch folder left beside it is removed by the next writer. A write that fails (a full disk) stops
  before the exchange: the message says nothing was written.
- **Stray temporaries** (`.<name>.<random>.tmp`, left by a killed writer of an older gsbench) are not
  carried into the new store; readers never read them (cell_files reads `*.json` only).
"""
from __future__ import annotations

import logging
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Iterable, Optional

from gsbench.errors import InputError, shorten
from gsbench.grids.store_format import SHARED_DIR, remove_unused_parts, write_record
from gsbench.outdir import exchange, lock_path, remove_left_scratch, resolved
from gsbench.runlock import RunLock

log = logging.getLogger(__name__)

SCRATCH_MARK = ".gsbench-publish"          # in a folder a writer may delete whole (its scratch, the old store)
TMP_NAME = re.compile(r"^\..+\.[a-z0-9_]{8}\.tmp$")   # write_bytes_atomic's temporaries


def scratch_prefix(store: Path) -> str:
    return f".{store.name}.publish-"


def refuse_links(store: Path) -> None:
    """The one-line refusal of a symbolic link anywhere under the store (not followed)."""
    _refuse(store / SHARED_DIR)                 # first: the link the prune would have followed
    for root, dirs, files in os.walk(store):
        for name in sorted(dirs + files):
            _refuse(Path(root) / name)


def _refuse(link: Path) -> None:
    if os.path.islink(link):
        raise InputError(f"{shorten(link)}: a symbolic link in the results store; publishing writes and prunes "
                         "only plain files and folders and never follows a link: replace it by the folder or "
                         "file itself; nothing was written")


def _safe_name(name: str, what: str) -> str:
    if not name or name in (".", "..") or "/" in name or "\\" in name or "\0" in name:
        raise InputError(f"{what} {shorten(repr(name), 60)}: not a plain file or folder name; nothing was written")
    return name


class StoreWriter:
    """The lock on a store, and its all-or-nothing commit (module docstring)."""

    def __init__(self, store: str | os.PathLike, command: str) -> None:
        store = Path(os.path.abspath(store))
        self.store = resolved(store) if store.is_symlink() else store    # the folder, not a link to it
        self.command = command
        self._lock: Optional[RunLock] = None
        self._seen: dict[str, tuple] = {}          # the store's files at the copy: rel -> signature

    def __enter__(self) -> "StoreWriter":
        if self.store.exists() and not self.store.is_dir():
            raise InputError(f"{shorten(self.store)}: exists and is not a folder (a results store is a folder of "
                             "<grid>/<run_id>.json files)")
        self.store.parent.mkdir(parents=True, exist_ok=True)
        self._lock = RunLock(self.store, self.command, lock_path=lock_path(self.store),
                             what="results store").acquire()
        try:
            if self.store.exists():
                refuse_links(self.store)
            self._remove_left_scratch()
        except BaseException:
            self._lock.release()
            raise
        return self

    def __exit__(self, *exc) -> None:
        if self._lock is not None:
            self._lock.release()

    # ------------------------------------------------------------------ scratch folders
    def _remove_left_scratch(self) -> None:
        """Scratch folders and old stores a killed writer left beside the store (marked; under the lock,
        so none is in use), and its mark in the store itself."""
        remove_left_scratch(self.store.parent, scratch_prefix(self.store), SCRATCH_MARK)
        mark = self.store / SCRATCH_MARK
        if mark.is_file() and not mark.is_symlink():
            mark.unlink()

    def _link_tree(self, scratch: Path) -> None:
        """Every file of the store into `scratch` as a hard link (a copy where links fail); the
        scratch mark and stray temporaries are left out. Their signatures go to self._seen."""
        for root, dirs, files in os.walk(self.store):
            rel_root = os.path.relpath(root, self.store)
            for d in dirs:
                (scratch / rel_root / d).mkdir()
            for f in files:
                rel = os.path.normpath(os.path.join(rel_root, f))
                src = self.store / rel
                st = os.lstat(src)
                self._seen[rel] = (st.st_ino, st.st_dev, st.st_size, st.st_mtime_ns)
                if rel == SCRATCH_MARK or TMP_NAME.match(f):
                    continue
                try:
                    os.link(src, scratch / rel, follow_symlinks=False)
                except OSError:
                    shutil.copy2(src, scratch / rel, follow_symlinks=False)

    def _stage(self, scratch: Path, writes: Iterable[dict], removes: Iterable[tuple[str, str]]) -> list[Path]:
        """The new store in the scratch folder beside the old one; the parts pruned."""
        (scratch / SCRATCH_MARK).write_bytes(b"")
        self._seen = {}
        if self.store.exists():
            self._link_tree(scratch)
        for grid, run_id in removes:
            p = scratch / _safe_name(grid, "grid") / f"{_safe_name(run_id, 'run id')}.json"
            if p.is_file():
                p.unlink()
        for rec in writes:
            grid, run_id = _safe_name(str(rec["grid"]), "grid"), _safe_name(str(rec["run_id"]), "run id")
            write_record(scratch, scratch / grid / f"{run_id}.json", rec)
        pruned = remove_unused_parts(scratch)
        return [self.store / p.relative_to(scratch) for p in pruned]

    def commit(self, writes: Iterable[dict], removes: Iterable[tuple[str, str]] = ()) -> list[Path]:
        """Write the records, delete the (grid, run id) cells, prune the parts no cell uses, as one
        change of the store (module docstring); the pruned parts' paths."""
        assert self._lock is not None, "commit needs the lock: use StoreWriter as a context manager"
        scratch: Optional[Path] = None
        try:
            scratch = Path(tempfile.mkdtemp(prefix=f"{scratch_prefix(self.store)}{os.getpid()}-",
                                            dir=self.store.parent))
            pruned = self._stage(scratch, list(writes), list(removes))
            if self.store.exists():
                (self.store / SCRATCH_MARK).write_bytes(b"")      # the old store, once swapped out, is removable
        except OSError as e:
            if scratch is not None:
                shutil.rmtree(scratch, ignore_errors=True)
            name = str(e.filename or self.store)
            where = shorten(str(self.store) + name[len(str(scratch)):] if scratch and name.startswith(str(scratch))
                            else name)
            raise InputError(f"{where}: cannot write ({e.strerror or e}); nothing was written: the results store "
                             f"{shorten(self.store)} is as it was") from None
        except BaseException:
            if scratch is not None:
                shutil.rmtree(scratch, ignore_errors=True)
            raise
        if self.store.exists():
            exchange(scratch, self.store)
            os.unlink(self.store / SCRATCH_MARK)
            self._remove_old(scratch)
        else:
            os.rename(scratch, self.store)
            os.unlink(self.store / SCRATCH_MARK)
        return pruned

    def _remove_old(self, old: Path) -> None:
        """Delete the swapped-out store: the files seen when it was copied (unchanged since) and its
        folders; a file that appeared meanwhile is kept there, and said (the folder loses its mark)."""
        kept = []
        for root, dirs, files in os.walk(old, topdown=False):
            for f in files:
                p = Path(root) / f
                rel = os.path.normpath(os.path.relpath(p, old))
                st = os.lstat(p)
                if rel == SCRATCH_MARK or self._seen.get(rel) == (st.st_ino, st.st_dev, st.st_size, st.st_mtime_ns):
                    p.unlink()
                else:
                    kept.append(rel)
            for d in dirs:
                try:
                    (Path(root) / d).rmdir()
                except OSError:
                    pass
        try:
            old.rmdir()
        except OSError:
            log.warning("%s: the old results store is kept here: it holds files that appeared while it was "
                        "rewritten (e.g. %s)", old, kept[0] if kept else "?")


__all__ = ["StoreWriter", "SCRATCH_MARK", "refuse_links", "scratch_prefix"]
