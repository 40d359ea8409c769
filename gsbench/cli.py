"""The `gsbench` command line. Each sub-command lives in gsbench/commands/<name>.py with
`add_arguments(parser)` and `run(args) -> int`; it is imported only when used."""
from __future__ import annotations

import argparse
import errno
import importlib
import sys
from typing import Optional, Sequence

COMMANDS = {
    "make-scene": ("make_scene", "generate a synthetic scene (analytic ray caster) in 3D-OVS / LERF-OVS layouts"),
    "train": ("train", "train a method (gaussiands, vanilla, twostage) on a scene into a run folder"),
    "eval": ("eval", "evaluate a trained run, or score a folder of predicted masks against a layout"),
    "ablate": ("ablate", "run an ablation / noise grid (local process pool or submitit)"),
    "collect": ("collect", "gather every results.json under a folder into one table"),
    "report": ("report", "write tables, plots and a static HTML report from collected results"),
    "stress": ("stress", "run the numerical stress battery against float64 references"),
    "points": ("points", "triangulate sparse points from known poses (SIFT + pycolmap) into sparse/0"),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="gsbench", description="Benchmark harness for semantic 3D Gaussian Splatting.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(_module=module)
        _load(module).add_arguments(p)
    return parser


def _load(module: str):
    return importlib.import_module(f"gsbench.commands.{module}")


def one_line(e: BaseException) -> str:
    """The error as one line: OS errors as 'path: problem', multi-line messages (YAML parsers) joined."""
    if isinstance(e, OSError) and e.filename is not None and e.strerror:
        msg = f"{e.filename}: {e.strerror}"
        if e.errno in (errno.EEXIST, errno.ENOTDIR):
            msg += " (a part of this path is a file, not a folder)"
        elif e.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
            msg += " (not writable/readable by this user)"
    else:
        msg = str(e)
    return " | ".join(line.strip() for line in msg.splitlines() if line.strip()) or type(e).__name__


def main(argv: Optional[Sequence[str]] = None) -> int:
    from gsbench.errors import InputError, NonFiniteError, NotBuiltError

    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    try:
        return int(_load(args._module).run(args) or 0)
    except NotBuiltError as e:
        print(f"gsbench {args.command}: not built yet: {e}", file=sys.stderr)
        return 3
    except (InputError, ValueError, NonFiniteError, OSError) as e:
        print(f"gsbench {args.command}: error: {one_line(e)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"gsbench {args.command}: interrupted; finished work is saved, re-run to resume", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
