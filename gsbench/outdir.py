"""Output folders gsbench owns: a command writes its folder whole or not at all, and never deletes or
overwrites a file it did not write.

    with OwnedFolder(out, "gsbench report", force=False) as folder:
        ...   # write everything under folder.staging
        folder.commit()

- The command writes into a fresh staging folder beside OUT (`.OUT.staging-<pid>-<random>`), and
  `commit` swaps it in: on Linux one rename exchanges the two folders (renameat2 RENAME_EXCHANGE),
  elsewhere three renames (OUT is missing for that moment). Until then OUT is the old, complete
  folder: a killed or failing command leaves it as it was (the next command into OUT removes the
  staging folder it left).
- OUT/.gsbench-manifest.json lists every file and folder the command wrote, with each file's size and
  sha256. Anything under OUT the manifest does not list, or a file changed since, is foreign: the
  folder is refused with one line naming one of them, unless `force`. With `force` the foreign files
  are kept: hard-linked into the new folder at the same place (a foreign file where the command
  writes one of its own is refused even so). Of the old folder only what the manifest vouches for
  is deleted.
- One writer at a time: a lock file beside OUT (`.OUT.writer.lock`, gsbench.runlock); a second
  command into OUT fails at once with one line naming the holder.
- OUT is never the file system's root, and a path whose symbolic links loop is one line.

A run folder (`gsbench train --out RUN`) is written file by file, so it has no manifest: it is a run's
when it holds a run's config.json, and then only the run's own names (gsbench.rundir) and what a
killed writer leaves; without one, nothing but the lock (`check_run_folder`). It is never the root,
the scene folder, gsbench's project tree or the published results store.
"""
from __future__ import annotations

import ctypes
import errno
import functools
import glob
import hashlib
import logging
import os
import shutil
import stat
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Optional

from gsbench import rundir
from gsbench.errors import InputError, shorten
from gsbench.runlock import RunLock
from gsbench.store import new_folder_mode, read_json, write_json_atomic

log = logging.getLogger(__name__)

MANIFEST = ".gsbench-manifest.json"
STAGING_MARK = ".gsbench-staging"       # in a staging folder until it is swapped in
_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


def lock_path(out: Path) -> Path:
    """The writer lock of OUT, beside it (OUT itself is swapped)."""
    return out.parent / f".{out.name}.writer.lock"


def staging_prefix(out: Path) -> str:
    return f".{out.name}.staging-"


def foreign_message(folder: Path, first: str, command: str, force_hint: bool = True) -> str:
    """The one-line refusal of a folder holding things `command` did not write, naming one of them."""
    how = "choose another --out or move them away" + (", or pass --force to keep them beside the new output"
                                                       if force_hint else "")
    return (f"{folder}: holds files that {command} did not write (or that changed since), e.g. {first}; "
            f"it never deletes or overwrites them: {how}")


# ------------------------------------------------------------------ what a folder holds
def _tree(root: Path, rel: str = "") -> Iterator[tuple[str, str]]:
    """(relative path, kind) of everything under `root`, in name order, the files of a folder before
    its sub-folders. kind: "file" (anything but a folder; links are not followed), "dir", "empty"
    (a folder with nothing in it)."""
    with os.scandir(root / rel if rel else root) as it:
        entries = sorted(it, key=lambda en: en.name)
    if rel and not entries:
        yield rel, "empty"
    subdirs = []
    for en in entries:
        r = f"{rel}/{en.name}" if rel else en.name
        if en.is_dir(follow_symlinks=False):
            subdirs.append(r)
        else:
            yield r, "file"
    for r in subdirs:
        yield r, "dir"
        yield from _tree(root, r)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _signature(path: Path) -> tuple[int, int, int, int]:
    st = os.lstat(path)
    return st.st_ino, st.st_dev, st.st_size, st.st_mtime_ns


def write_manifest(folder: Path, command: str) -> None:
    """FOLDER/.gsbench-manifest.json: every file (size, sha256) and folder now under FOLDER."""
    files, folders = {}, []
    for rel, kind in _tree(folder):
        if kind == "dir":
            folders.append(rel)
        elif kind == "file" and rel not in (MANIFEST, STAGING_MARK):
            files[rel] = {"size": os.lstat(folder / rel).st_size, "sha256": _sha256(folder / rel)}
    write_json_atomic(folder / MANIFEST, {"command": command, "files": files, "folders": folders})


def read_manifest(folder: Path, command: str) -> tuple[dict[str, dict], set[str]]:
    """The files and folders FOLDER's manifest lists when `command` wrote it; nothing when it is
    absent, unreadable or another command's (then it vouches for nothing: all in FOLDER is foreign)."""
    try:
        data = read_json(folder / MANIFEST)
    except (InputError, OSError):
        return {}, set()
    if not isinstance(data, dict) or data.get("command") != command or not isinstance(data.get("files"), dict):
        return {}, set()
    files = {k: v for k, v in data["files"].items() if isinstance(v, dict)}
    folders = {d for d in data.get("folders") or [] if isinstance(d, str)}
    return files, folders


def _vouched(path: Path, record: Optional[dict]) -> bool:
    """A regular file of the size and sha256 the manifest recorded."""
    if record is None:
        return False
    st = os.lstat(path)
    return stat.S_ISREG(st.st_mode) and record.get("size") == st.st_size and record.get("sha256") == _sha256(path)


@dataclass
class Survey:
    """What a folder holds: files its manifest vouches for (with their signature at the survey) and
    the paths it does not (foreign: files, and empty folders it does not list)."""
    owned: dict[str, tuple] = field(default_factory=dict)
    foreign: list[str] = field(default_factory=list)


def survey(folder: Path, command: str, first_only: bool = False) -> Survey:
    """Sort what is under `folder` into owned (by `command`) and foreign; `first_only` stops at the
    first foreign path (a refusal needs one, and OUT may be a big folder given by mistake)."""
    out = Survey()
    if not folder.is_dir():
        return out
    listed, folders = read_manifest(folder, command)
    for rel, kind in _tree(folder):
        if kind == "dir":
            continue
        if kind == "empty":
            ours = rel in folders
        else:
            ours = rel == MANIFEST or _vouched(folder / rel, listed.get(rel))
            if ours:
                out.owned[rel] = _signature(folder / rel)
        if not ours:
            out.foreign.append(rel)
            if first_only:
                break
    return out


# ------------------------------------------------------------------ swapping
@functools.lru_cache(maxsize=1)
def _renameat2():
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):    # not Linux / glibc before 2.28
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


def exchange(a: Path, b: Path) -> None:
    """Swap two folders: in one step where the system can, else by three renames."""
    fn = _renameat2()
    if fn is not None:
        if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
            return
        err = ctypes.get_errno()
        if err not in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
            raise OSError(err, os.strerror(err), str(b))
    log.debug("%s: no atomic exchange here; swapping by three renames", b)
    aside = a.with_name(a.name + "-old")
    os.rename(b, aside)
    os.rename(a, b)
    os.rename(aside, a)


def _remove_owned(old: Path, before: Survey, kept: list[str], new: Path) -> None:
    """Delete from the swapped-out folder what the survey found ours (unchanged since) and the old
    names of kept files (now linked into the new folder); keep anything else, and say so."""
    tree = list(_tree(old))
    for rel, kind in tree:
        if kind != "file":
            continue
        p, sig = old / rel, before.owned.get(rel)
        ours = sig is not None and _signature(p) == sig
        linked = rel in kept and os.path.lexists(new / rel) and _signature(p)[:2] == _signature(new / rel)[:2]
        if ours or linked:
            p.unlink()
    for rel, kind in reversed(tree):      # deepest first
        if kind != "file":
            try:
                (old / rel).rmdir()
            except OSError:
                pass
    try:
        old.rmdir()
    except OSError:
        left = next((rel for rel, _ in _tree(old)), "?")
        log.warning("%s: the old %s is kept here: it holds files that appeared while it was rewritten "
                    "(e.g. %s)", old, new, left)


def _clashes(staging: Path, rel: str) -> bool:
    """Something of the new output at `rel`, or a file where one of its parent folders would be."""
    p = staging / rel
    if os.path.lexists(p) or rel == STAGING_MARK:
        return True
    return any(os.path.lexists(q) and not q.is_dir() for q in p.parents if staging in q.parents)


def resolved(out: str | os.PathLike) -> Path:
    """OUT as an absolute path with every link followed; a symbolic link loop (or a link chain too
    long to follow) is one InputError naming OUT, not the RuntimeError pathlib raises."""
    try:
        return Path(os.path.abspath(out)).resolve()
    except (RuntimeError, OSError) as e:
        why = e.strerror if isinstance(e, OSError) and e.strerror else "a loop of symbolic links"
        raise InputError(f"{shorten(out)}: cannot be used as a folder: {why} (a symbolic link in it "
                         "points back to itself); give another path") from None


def _check_target(out: Path) -> None:
    """OUT is a folder or can be one: a file there, or where a parent folder should be, is refused
    (the latter with the error every writer gives, ENOTDIR); so are a path whose links loop and the
    file system's root (it has no parent to hold the lock and the staging folder beside it)."""
    real = resolved(out)
    if real.parent == real:
        raise InputError(f"{out}: refused: the root of the file system is not an output folder; "
                         "give a folder of its own")
    for parent in out.parents:
        if parent.exists():
            if not parent.is_dir():
                raise NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR), str(out))
            break
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")


def refuse_foreign(out: str | os.PathLike, command: str, force_hint: bool = True) -> None:
    """The one-line refusal when OUT holds anything `command` did not write: a check before long work
    (OwnedFolder checks again, under OUT's lock, before it writes)."""
    out = Path(out)
    _check_target(out)
    s = survey(out, command, first_only=True)
    if s.foreign:
        raise InputError(foreign_message(out, s.foreign[0], command, force_hint))


def remove_left_scratch(parent: Path, prefix: str, mark: str) -> None:
    """Folders a killed command left in `parent` (named `prefix`..., holding the file `mark`, so nothing
    else is ever removed); called under the lock of what they stage, so none of them is being written."""
    for d in parent.glob(glob.escape(prefix) + "*"):
        if d.is_dir() and not d.is_symlink() and (d / mark).is_file():
            shutil.rmtree(d, ignore_errors=True)


def _remove_left_staging(out: Path) -> None:
    """Staging folders a killed command left beside OUT."""
    remove_left_scratch(out.parent, staging_prefix(out), STAGING_MARK)


class OwnedFolder:
    """OUT written whole by one command: staged beside it, swapped in by `commit`."""

    def __init__(self, out: str | os.PathLike, command: str, force: bool = False, force_hint: bool = True,
                 what: str = "output folder") -> None:
        out = Path(os.path.abspath(out))
        self.out = resolved(out) if out.is_symlink() else out    # swap the folder, not a link to it
        self.command = command
        self.force = force
        self.force_hint = force_hint
        self.what = what
        self.staging: Optional[Path] = None
        self.kept: list[str] = []
        self._lock: Optional[RunLock] = None
        self._swapped = False

    def _survey(self, first_only: bool = False) -> Survey:
        s = survey(self.out, self.command, first_only=first_only and not self.force)
        if s.foreign and not self.force:
            raise InputError(foreign_message(self.out, s.foreign[0], self.command, self.force_hint))
        return s

    def __enter__(self) -> "OwnedFolder":
        _check_target(self.out)
        self._lock = RunLock(self.out, self.command, lock_path=lock_path(self.out), what=self.what).acquire()
        try:
            self._survey(first_only=True)           # refuse early, before the command's work
            _remove_left_staging(self.out)
            prefix = f"{staging_prefix(self.out)}{os.getpid()}-"
            self.staging = Path(tempfile.mkdtemp(prefix=prefix, dir=self.out.parent))
            os.chmod(self.staging, new_folder_mode())     # it becomes OUT: a folder's mode, not mkdtemp's 0700
            (self.staging / STAGING_MARK).write_bytes(b"")
        except BaseException:
            self._lock.release()
            raise
        return self

    def _keep(self, foreign: list[str]) -> None:
        """Hard-link each foreign path into the staging folder (force); one the command wrote too is refused."""
        assert self.staging is not None
        for rel in foreign:
            src, dst = self.out / rel, self.staging / rel
            if src.is_dir() and not src.is_symlink() and dst.is_dir():
                continue                     # an empty folder the new output has too
            if _clashes(self.staging, rel):
                raise InputError(f"{src}: not written by {self.command}, which writes this path itself; "
                                 "--force keeps such files but never overwrites them: move it away")
            try:
                if src.is_dir() and not src.is_symlink():
                    dst.mkdir(parents=True, exist_ok=True)
                else:
                    dst.parent.mkdir(parents=True, exist_ok=True)
                    os.link(src, dst, follow_symlinks=False)
            except OSError as e:
                raise InputError(f"{src}: cannot keep it in the new folder ({e.strerror}); move it away") from None
        self.kept = list(foreign)

    def commit(self) -> None:
        """Write the manifest, keep foreign files (force), swap the staging folder in, delete the old
        folder's own files."""
        assert self.staging is not None and self._lock is not None
        write_manifest(self.staging, self.command)
        before = self._survey()      # again: the folder may have changed while the command ran
        self._keep(before.foreign)
        (self.staging / STAGING_MARK).unlink()
        if self.out.exists():
            exchange(self.staging, self.out)
            self._swapped = True
            _remove_owned(self.staging, before, self.kept, self.out)
        else:
            os.rename(self.staging, self.out)
            self._swapped = True

    def __exit__(self, *exc) -> None:
        try:
            if not self._swapped and self.staging is not None:
                shutil.rmtree(self.staging, ignore_errors=True)
        finally:
            if self._lock is not None:
                self._lock.release()


# ------------------------------------------------------------------ run folders (gsbench train --out)
#: what a run folder holds at its top level (gsbench.rundir), and the folder of the report's pictures
RUN_NAMES = frozenset((rundir.CONFIG, rundir.ENV, rundir.STATUS, rundir.CHECKPOINT, rundir.TRAIN_LOG,
                       rundir.TRAIN_SUMMARY, rundir.MODEL, rundir.RESULTS, rundir.CELL, rundir.CELL_STATUS))
RUN_FOLDERS = frozenset((rundir.PREVIEWS,))
#: the folders of gsbench's own project tree (a checkout), where no run is written
PROJECT_FOLDERS = ("gsbench", "methods", "datasets", "metrics", "reports", "docs", "tests", "scripts", "benchmarks",
                   "results", ".git")
STORE_MARK = "_shared"       # the shared parts folder of a published results store (gsbench.grids.store_format)


def _leftover(name: str) -> bool:
    """What a killed run writer leaves: an atomic write's temporary file, a lock takeover's, the
    previews' staging folder."""
    return name.startswith(".") and (name.endswith(".tmp") or name.startswith(f".{rundir.LOCK}.")
                                     or name.startswith(f".{rundir.PREVIEWS}."))


def _is_run_config(path: Path) -> bool:
    """A run's config.json: a JSON object naming a method, the scene it was trained on and its run id."""
    try:
        data = read_json(path)
    except (InputError, OSError):
        return False
    return (isinstance(data, dict) and isinstance(data.get("method"), str) and isinstance(data.get("run_id"), str)
            and isinstance(data.get("scene"), dict))


def first_foreign_in_run(out: Path) -> Optional[str]:
    """The first entry of OUT (in name order) that is not a run's, or None. A run writes its
    config.json first (after its lock): without a run's config.json only the lock and a killed
    writer's leftovers are a run's, so a user's env.json or model.pt is never taken for one."""
    if not out.is_dir():
        return None
    has_config = (out / rundir.CONFIG).is_file() and not (out / rundir.CONFIG).is_symlink() \
        and _is_run_config(out / rundir.CONFIG)
    with os.scandir(out) as it:
        entries = sorted(it, key=lambda en: en.name)
    for en in entries:
        name = en.name
        if en.is_symlink():
            return name
        if name in (rundir.LOCK, rundir.LOCK + ".takeover", rundir.CELL, rundir.CELL_STATUS) or _leftover(name):
            continue
        if has_config and (name in RUN_NAMES and en.is_file() or name in RUN_FOLDERS and en.is_dir()):
            continue
        return name
    return None


def project_root() -> Optional[Path]:
    """The root of the gsbench checkout this code runs from (the folder above the package holding
    pyproject.toml), or None for an installed package."""
    root = Path(__file__).resolve().parent.parent
    return root if (root / "pyproject.toml").is_file() else None


def _within(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def _store_around(real: Path) -> Optional[Path]:
    """The published results store OUT is (or is inside): a folder holding the store's `_shared` parts."""
    for folder in (real, *real.parents):
        try:
            if (folder / STORE_MARK).is_dir() and not (folder / STORE_MARK).is_symlink():
                return folder
        except OSError:      # a path too long to look into: the writer's own error names it next
            continue
    return None


def _refuse_place(out: Path, real: Path, scene: Optional[Path]) -> None:
    """Refuse a run folder at the root, in the scene, in gsbench's project tree or in the store."""
    where = None
    if real.parent == real:
        where = "the root of the file system"
    elif scene is not None and _within(real, resolved(scene)):
        where = f"the scene folder {resolved(scene)} (or inside it): run files would mix with the scene's"
    elif (store := _store_around(real)) is not None:
        where = f"the published results store {store} (or inside it), which only gsbench publish writes"
    else:
        root = project_root()
        pkg = Path(__file__).resolve().parent
        if root is not None and (real == root or any(_within(real, root / f) for f in PROJECT_FOLDERS)):
            where = f"gsbench's own project tree {root} (its root or one of its source folders)"
        elif _within(real, pkg):
            where = f"gsbench's installed package {pkg}"
    if where:
        raise InputError(f"{out}: refused as a run folder: it is {where}; give --out a folder of its own")


def check_run_folder(out: str | os.PathLike, scene: Optional[str | os.PathLike] = None) -> None:
    """The one-line refusal of a `gsbench train --out` that is not a run's folder to write: a place
    no run belongs (the root, the scene folder, gsbench's project tree, the published store), a file,
    or a folder holding anything that is not a run's (one named). A new or empty folder, or a run
    folder to resume, passes."""
    out = Path(out)
    real = resolved(out)
    _refuse_place(out, real, Path(scene) if scene is not None else None)
    _check_target(out)
    first = first_foreign_in_run(real)
    if first is not None:
        raise InputError(f"{out}: holds files that are not a gsbench run's, e.g. {first}; gsbench train never "
                         "overwrites them: give --out a new or empty folder (or a run folder to resume)")
