"""The `gsbench` command line. Each sub-command lives in gsbench/commands/<name>.py with
`add_arguments(parser)` and `run(args) -> int`. Building the parser imports every command module, so
a command imports its heavy parts inside `run` (marked `# lazy: start-up`, docs/architecture.md).

Errors a user can act on (gsbench.errors.InputError and its subclasses, NonFiniteError, OSError)
are printed as one line with exit status 1; anything else is a bug and propagates with its
traceback. `--debug` (or GSBENCH_DEBUG=1) shows the traceback of the one-line errors too.
"""
from __future__ import annotations

import argparse
import errno
import importlib
import logging
import os
import sys
from typing import Optional, Sequence

from gsbench import startup
from gsbench.errors import InputError, NonFiniteError, Terminated, bounded_line, interrupted

COMMANDS = {
    "make-scene": ("make_scene", "generate a synthetic scene (analytic ray caster) in 3D-OVS / LERF-OVS layouts"),
    "train": ("train", "train a registered method on a scene into a run folder"),
    "eval": ("eval", "evaluate a trained run, or score a folder of predicted masks against a layout"),
    "ablate": ("ablate", "run an ablation / noise grid (local process pool or submitit)"),
    "claims": ("claims", "run every grid the paper-claims table needs, then print the table and write the report"),
    "publish": ("publish", "add finished claims cells to the published store (results/cpu), list stale ones, "
                           "generate docs/claims.md"),
    "verify": ("verify", "re-run published cells drawn at random and compare every metric"),
    "collect": ("collect", "gather every results.json under a folder into one table"),
    "report": ("report", "write tables, plots and a static HTML report from collected results"),
    "stress": ("stress", "run the numerical stress battery against float64 references"),
    "points": ("points", "triangulate sparse points from known poses (SIFT + pycolmap) into sparse/0"),
    "data": ("data", "dataset folders: `data check PATH` lists the layout, labels and every problem"),
    "doctor": ("doctor", "check this machine: torch, CUDA devices, gsplat's CUDA extension, numba, what auto picks"),
}
LOG_FORMAT = "gsbench: %(message)s"
DEBUG_LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


class _Parser(argparse.ArgumentParser):
    """argparse, its usage errors bounded too (an invalid choice echoes the value given)."""

    def error(self, message: str):  # type: ignore[override]
        super().error(bounded_line(message))


def _global_flags(suppress: bool) -> argparse.ArgumentParser:
    """--debug / --quiet / --verbose, accepted before or after the sub-command."""
    d = {"default": argparse.SUPPRESS} if suppress else {}
    p = _Parser(add_help=False)
    p.add_argument("--debug", action="store_true", help="show the traceback of errors (or set GSBENCH_DEBUG=1)", **d)
    g = p.add_mutually_exclusive_group()
    g.add_argument("-q", "--quiet", action="store_true", help="warnings and errors only, no progress bars", **d)
    g.add_argument("-v", "--verbose", action="store_true", help="debug messages too", **d)
    return p


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="gsbench",
        description="Benchmark harness for semantic 3D Gaussian Splatting.",
        parents=[_global_flags(suppress=False)],
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text, parents=[_global_flags(suppress=True)])
        p.set_defaults(_module=module)
        _load(module).add_arguments(p)
    return parser


def _load(module: str):
    return importlib.import_module(f"gsbench.commands.{module}")


def configure_logging(quiet: bool = False, verbose: bool = False) -> int:
    """One stderr handler on the `gsbench` logger (replaced, not added, when called again): WARNING
    with --quiet, DEBUG with --verbose, INFO otherwise. Returns the level."""
    level = logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO
    logger = logging.getLogger("gsbench")
    for h in [h for h in logger.handlers if getattr(h, "_gsbench_cli", False)]:
        logger.removeHandler(h)
    handler = logging.StreamHandler(sys.stderr)
    handler._gsbench_cli = True  # type: ignore[attr-defined]
    handler.setFormatter(logging.Formatter(DEBUG_LOG_FORMAT if verbose else LOG_FORMAT))
    logger.addHandler(handler)
    logger.setLevel(level)
    logger.propagate = False
    return level


def apply_global_flags(args: argparse.Namespace) -> argparse.Namespace:
    """Logging level from --quiet/--verbose; --quiet also turns the command's progress bars off."""
    quiet = bool(getattr(args, "quiet", False))
    configure_logging(quiet=quiet, verbose=bool(getattr(args, "verbose", False)))
    if quiet and hasattr(args, "no_progress"):
        args.no_progress = True
    return args


def debug_requested(args: argparse.Namespace) -> bool:
    return bool(getattr(args, "debug", False)) or os.environ.get("GSBENCH_DEBUG", "") not in ("", "0")


def one_line(e: BaseException) -> str:
    """The error as one line: OS errors as 'path: problem', multi-line messages (YAML parsers) joined,
    every long name, path or value in it shortened (gsbench.errors.bounded_line)."""
    if isinstance(e, OSError) and e.filename is not None and e.strerror:
        msg = f"{e.filename}: {e.strerror}"
        if e.errno in (errno.EEXIST, errno.ENOTDIR):
            msg += " (a part of this path is a file, not a folder)"
        elif e.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
            msg += " (not writable/readable by this user)"
    else:
        msg = str(e)
    return bounded_line(msg) or type(e).__name__


def main(argv: Optional[Sequence[str]] = None) -> int:
    startup()
    parser = build_parser()
    args = apply_global_flags(parser.parse_args(argv))
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    try:
        return int(_load(args._module).run(args) or 0)
    except (InputError, NonFiniteError, OSError) as e:
        if debug_requested(args):
            raise
        print(f"gsbench {args.command}: error: {one_line(e)}", file=sys.stderr)
        return 1
    except (KeyboardInterrupt, SystemError) as e:
        if debug_requested(args) or not interrupted(e):   # a SystemError that is not Ctrl-C is a bug
            raise
        if isinstance(e, Terminated):
            print(f"gsbench {args.command}: terminated (SIGTERM); finished work is saved, re-run to resume",
                  file=sys.stderr)
            return 143
        print(f"gsbench {args.command}: interrupted; finished work is saved, re-run to resume", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
