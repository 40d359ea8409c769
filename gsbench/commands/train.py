"""`gsbench train --method M --scene PATH [--preset P] [--set key=value ...] --out RUN_DIR`."""
from __future__ import annotations

import argparse
from pathlib import Path

from gsbench import rundir
from gsbench.config import load_config, set_args
from gsbench.method_table import METHODS
from gsbench.store import read_json


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--method", required=True, choices=METHODS,
                        help="method to train")
    parser.add_argument("--scene", required=True, help="scene folder (any layout gsbench.datasets reads)")
    parser.add_argument("--preset", default=None, help="config preset: cpu-small, paper, or a .yaml path")
    parser.add_argument("--set", dest="overrides", nargs="+", action="append", default=[], metavar="KEY=VALUE",
                        help="override config keys, e.g. --set train.iterations=300 (repeatable)")
    parser.add_argument("--out", required=True, help="run folder to write (resumed if it holds a checkpoint)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def config_from_args(args: argparse.Namespace) -> dict:
    """The config this command trains with (default <- --preset <- every --set)."""
    return load_config(args.method, args.preset, set_args(args.overrides))


def run(args: argparse.Namespace) -> int:
    from gsbench.runs import train_run  # lazy: start-up (cli loads all commands)

    cfg = config_from_args(args)
    out = train_run(cfg, Path(args.scene), Path(args.out), progress=not args.no_progress)
    s = read_json(out / rundir.TRAIN_SUMMARY)
    ev = s.get("last_eval") or {}
    psnr = ev.get("psnr")
    print(f"gsbench train: {s['status']} {out} method={s['method']} iterations={s['iterations']} "
          f"gaussians={s['n_gaussians']} train_s={s['train_s']:.1f} peak_rss_mb={s['peak_rss_mb']:.0f} "
          f"backend={s['backend']}" + (f" test_psnr={psnr:.2f}" if psnr is not None else ""))
    return 0
