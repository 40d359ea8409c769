"""One writer per run folder: a lock file naming the process that writes the folder.

    with RunLock(run_dir, "gsbench train ..."):
        ...   # train or evaluate into run_dir

RUN_DIR/writer.lock holds {pid, host, started, command, token}. It is created with O_EXCL, so of two
commands started into one folder the second gets RunLockedError (an InputError: one line, exit 1)
naming the holder. The holder is stale, and its lock is taken over, when it ran on this host and
its pid is dead or a zombie (a SIGKILLed process leaves its lock behind), or when it ran on another
host and has not refreshed the lock for `stale_after_s` (the holder touches it every HEARTBEAT_S).
Takeovers are made under an flock on a side file (removed again, so neither a winner nor a loser
leaves it behind), so two processes never take over the same stale lock together. The same
process may take a folder's lock again (a grid cell holds it for train + eval, and training inside
takes it again): only the outermost release removes it.

The lock file may also sit beside the folder it guards (`lock_path`): an output folder that is
swapped whole (gsbench.outdir) cannot hold its own lock.
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import os
import socket
import sys
import threading
import time
import uuid
from pathlib import Path
from typing import Iterator, Optional

from gsbench import rundir
from gsbench.errors import InputError
from gsbench.store import read_json

log = logging.getLogger(__name__)

LOCK_FILE = rundir.LOCK
HEARTBEAT_S = 10.0
STALE_AFTER_S = 120.0
_held: dict[str, int] = {}          # lock path -> nesting depth in this process
_held_guard = threading.Lock()


def pid_alive(pid: int) -> bool:
    """True when `pid` is a live process. A zombie (killed, not yet reaped: workers of a killed
    grid are re-parented to an init that may never reap them) counts as dead."""
    if pid <= 0:
        return False   # 0 and negatives address process groups, not a process
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True   # no /proc (not Linux): trust kill(0)
    # the state letter follows the parenthesised command name, which may itself contain spaces
    return stat[stat.rfind(")") + 2:][:1] not in ("Z", "X")


class RunLockedError(InputError):
    """The run folder is being written by another live process."""


def read_holder(run_dir: str | os.PathLike) -> Optional[dict]:
    """The lock's holder record, or None when the folder is not locked (or the file is unreadable)."""
    return _read_lock(Path(run_dir) / LOCK_FILE)


def _read_lock(lock_path: Path) -> Optional[dict]:
    try:
        data = read_json(lock_path)
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


@contextlib.contextmanager
def _flocked(guard: Path) -> Iterator[None]:
    """An exclusive flock on `guard`, which is removed when released. A waiter that got the lock on
    a file already removed (or replaced) opens the path again, so two holders never coexist."""
    while True:
        fd = os.open(guard, os.O_CREAT | os.O_RDWR, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            st = os.fstat(fd)
            try:
                now = os.stat(guard)
                current = (now.st_ino, now.st_dev) == (st.st_ino, st.st_dev)
            except FileNotFoundError:
                current = False
        except BaseException:
            os.close(fd)
            raise
        if current:
            break
        os.close(fd)
    try:
        yield
    finally:
        try:
            os.unlink(guard)
        except FileNotFoundError:
            pass
        os.close(fd)


def holder_is_stale(holder: dict, lock_path: Path, stale_after_s: float = STALE_AFTER_S) -> bool:
    """Dead or zombie pid on this host; on another host, no refresh for stale_after_s."""
    if holder.get("host") == socket.gethostname():
        try:
            return not pid_alive(int(holder.get("pid", -1)))
        except (TypeError, ValueError):
            return True
    try:
        age = time.time() - lock_path.stat().st_mtime
    except OSError:
        return True
    return age > stale_after_s


def describe(holder: dict) -> str:
    started = holder.get("started")
    when = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(started)) if isinstance(started, (int, float)) else "?"
    return f"pid {holder.get('pid')} on {holder.get('host')} since {when} ({holder.get('command', '?')})"


class RunLock:
    """Context manager holding RUN_DIR/writer.lock (or `lock_path`) for this process; `what` names
    the folder in the error a second writer gets (run folder, runs folder, report folder)."""

    def __init__(self, run_dir: str | os.PathLike, command: Optional[str] = None,
                 stale_after_s: float = STALE_AFTER_S, lock_path: Optional[Path] = None,
                 what: str = "run folder") -> None:
        self.run_dir = Path(run_dir)
        self.path = Path(lock_path) if lock_path is not None else self.run_dir / LOCK_FILE
        self.what = what
        self.command = command or " ".join([Path(sys.argv[0]).name] + sys.argv[1:])
        self.stale_after_s = stale_after_s
        self.token = uuid.uuid4().hex
        self.took_over: Optional[dict] = None
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None

    def _record(self) -> bytes:
        return json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "started": time.time(),
                           "command": self.command, "token": self.token}).encode("utf-8")

    def _create(self) -> bool:
        try:
            fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            return False
        with os.fdopen(fd, "wb") as f:
            f.write(self._record())
            f.flush()
            os.fsync(f.fileno())
        return True

    def _take_over_if_stale(self) -> Optional[dict]:
        """Replace a stale lock by ours (under an flock, re-checking); returns the holder or None."""
        with _flocked(self.path.with_name(self.path.name + ".takeover")):
            holder = _read_lock(self.path)
            if holder is None and not self.path.exists():
                return {} if self._create() else None
            if holder is not None and not holder_is_stale(holder, self.path, self.stale_after_s):
                return None
            tmp = self.path.with_name(f".{self.path.name}.{self.token}")
            tmp.write_bytes(self._record())
            os.replace(tmp, self.path)
            return holder or {"note": "unreadable lock file"}

    def acquire(self) -> "RunLock":
        self.path.parent.mkdir(parents=True, exist_ok=True)
        key = str(self.path.resolve())
        with _held_guard:
            if _held.get(key):
                _held[key] += 1
                return self
        if not self._create():
            holder = _read_lock(self.path)
            if holder and holder.get("pid") == os.getpid() and holder.get("host") == socket.gethostname():
                self.token = holder.get("token", self.token)      # ours, from an earlier unreleased lock
            else:
                took = self._take_over_if_stale()
                if took is None:
                    holder = _read_lock(self.path) or {}
                    raise RunLockedError(f"{self.run_dir}: another process is writing this {self.what}: "
                                         f"{describe(holder)}; wait for it or remove {self.path} if it is gone")
                if took:
                    self.took_over = took
                    log.warning("%s: took over the lock of a stale writer (%s)", self.run_dir, describe(took))
        with _held_guard:
            _held[key] = 1
        self._thread = threading.Thread(target=self._refresh, daemon=True)
        self._thread.start()
        return self

    def _refresh(self) -> None:
        while not self._stop.wait(HEARTBEAT_S):
            try:
                os.utime(self.path)
            except OSError:
                pass

    def release(self) -> None:
        key = str(self.path.resolve())
        with _held_guard:
            depth = _held.get(key, 0) - 1
            if depth > 0:
                _held[key] = depth
                return
            _held.pop(key, None)
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        holder = _read_lock(self.path)
        if holder is not None and holder.get("token") == self.token:
            try:
                self.path.unlink()
            except FileNotFoundError:
                pass

    def __enter__(self) -> "RunLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
