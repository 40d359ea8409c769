"""The hostile-input battery: bad, huge or malicious input given to the real commands.

Each case writes its input into a fresh folder, runs one `gsbench` command on it in this process
(gsbench.cli.main) and checks what a user sees: a non-zero exit (or the exit the case names), one
error line starting "gsbench COMMAND: error:" that names the file and stays short, no traceback, and
no hang (each case has a time limit). A case may add its own check of the folder afterwards (e.g. a
user's file that must still be there). Rows join the numerical battery as components "hostile:AREA",
so `gsbench stress --component hostile` runs only these.

Why its own package, on the commands' floor: the cases run the command line itself. The cases live
by area in the modules of this package (config, data, eval, output); `hostile_cases` fixes their order.
"""
from __future__ import annotations

import contextlib
import functools
import io
import shutil
import signal
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

from gsbench.cli import main
from gsbench.errors import bounded_line
from gsbench.stress.core import Case, CaseResult

MAX_LINE = 400          # an error line longer than this echoes the input instead of naming it
DEFAULT_LIMIT_S = 60.0  # a case running longer is a hang


@dataclass(frozen=True)
class Hostile:
    """One hostile input. `build(folder)` writes it under `folder` and returns the gsbench argv;
    `expect` are substrings the error line must contain (the file's name, the problem); `check(folder,
    exit_code, stderr)` returns why the case failed, or None."""
    area: str
    name: str
    build: Callable[[Path], list[str]]
    expect: tuple[str, ...] = ()
    exit_code: Optional[int] = 1          # None: any exit is acceptable (the check decides)
    check: Optional[Callable[[Path, int, str], Optional[str]]] = None
    limit_s: float = DEFAULT_LIMIT_S


_BASE = {}


def _base_dir() -> Path:
    if "dir" not in _BASE:
        _BASE["dir"] = Path(tempfile.mkdtemp(prefix="gsbench-hostile-"))
    return _BASE["dir"]


@functools.lru_cache(maxsize=None)
def _tiny_scene() -> Path:
    out = _base_dir() / "scene"
    args = ["make-scene", "--preset", "tabletop-small", "--views", "8", "--resolution", "32x24", "--seed", "0"]
    if main([*args, "--out", str(out), "--quiet"]) != 0:
        raise RuntimeError("hostile battery: could not make the tiny scene")
    return out


def tiny_scene(dest: Path) -> Path:
    """A copy of a tiny synthetic scene (tabletop-small, 8 views at 32x24) at `dest`, to corrupt."""
    shutil.copytree(_tiny_scene(), dest)
    return dest


@functools.lru_cache(maxsize=None)
def _tiny_run(method: str) -> Path:
    out = _base_dir() / f"run_{method}"
    args = ["train", "--method", method, "--scene", str(_tiny_scene()), "--preset", "cpu-small", "--out", str(out),
            "--set", "train.iterations=2", "--set", "train.eval_every=0", "--set", "priors.masks.provider=gt",
            "--set", "semantic.autoencoder.epochs=2", "--no-progress", "--quiet"]
    if main(args) != 0:
        raise RuntimeError(f"hostile battery: could not train the tiny {method} run")
    return out


def tiny_run(dest: Path, method: str = "vanilla") -> Path:
    """A copy of a finished 2-step run of `method` on the tiny scene at `dest` (not evaluated)."""
    shutil.copytree(_tiny_run(method), dest)
    return dest


class _Timeout(Exception):
    pass


@contextlib.contextmanager
def _time_limit(seconds: float):
    """SIGALRM-based limit in the main thread; elsewhere no limit (signals need the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def _raise(signum, frame):
        raise _Timeout()
    old = signal.signal(signal.SIGALRM, _raise)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _judge(h: Hostile, folder: Path, argv: list[str], code: int, err: str) -> Optional[str]:
    """Why the case failed, or None."""
    if "Traceback" in err:
        return "traceback printed"
    if h.exit_code is not None and code != h.exit_code:
        return f"exit {code}, expected {h.exit_code}"
    if code not in (0, 130, 143):      # an interruption (Ctrl-C, SIGTERM) ends in its own line, not an error
        lines = [ln for ln in err.splitlines() if ln.strip()]
        prefix = f"gsbench {argv[0]}: error:"
        if not lines or not lines[-1].startswith(prefix):
            return f"last line is not '{prefix} ...'"
        if len(lines[-1]) > MAX_LINE:
            return f"error line of {len(lines[-1])} characters"
        missing = [e for e in h.expect if e not in lines[-1]]
        if missing:
            return f"error line lacks {missing!r}"
    return h.check(folder, code, err) if h.check is not None else None


def run_hostile(h: Hostile) -> CaseResult:
    """Build the input in a fresh folder, run the command, judge what the user saw."""
    t0 = time.perf_counter()
    res = CaseResult(f"hostile:{h.area}", h.name)
    folder = Path(tempfile.mkdtemp(prefix="case-", dir=_base_dir()))
    try:
        argv = h.build(folder)
        out, err = io.StringIO(), io.StringIO()
        with _time_limit(h.limit_s), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as e:    # argparse
                code = e.code if isinstance(e.code, int) else 2
        text = err.getvalue()
        why = _judge(h, folder, argv, code, text)
        last = ([ln for ln in text.splitlines() if ln.strip()] or [""])[-1]
        res.passed = why is None
        command = bounded_line(" ".join(["gsbench", *argv]).replace(str(folder), "DIR"))
        res.note = (why + ": " if why else "") + f"`{command}` -> exit {code}: {last[:MAX_LINE]}".replace(
            str(folder), "DIR")
    except _Timeout:
        res.note = f"hang: no answer within {h.limit_s:g} s"
    except BaseException as e:    # noqa: BLE001 - a case that raises is a failed row, never a crash
        if isinstance(e, KeyboardInterrupt):
            raise
        tb = traceback.format_exc().strip().splitlines()[-1]
        res.note = f"raised {type(e).__name__}: {tb[:MAX_LINE]}"
    finally:
        shutil.rmtree(folder, ignore_errors=True)
        res.seconds = time.perf_counter() - t0
    return res


def hostile_cases() -> list[Case]:
    """Every hostile case as a battery Case (component "hostile:AREA")."""
    from gsbench.commands.hostile.config import CASES as config_cases  # lazy: the area modules import this one
    from gsbench.commands.hostile.data import CASES as data_cases  # lazy: the area modules import this one
    from gsbench.commands.hostile.eval import CASES as eval_cases  # lazy: the area modules import this one
    from gsbench.commands.hostile.output import CASES as output_cases  # lazy: the area modules import this one
    from gsbench.commands.hostile.store import CASES as store_cases  # lazy: the area modules import this one
    out = []
    for h in [*config_cases, *data_cases, *eval_cases, *output_cases, *store_cases]:
        out.append(Case(f"hostile:{h.area}", h.name, functools.partial(run_hostile, h)))
    return out
