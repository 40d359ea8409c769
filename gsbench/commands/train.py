"""`gsbench train --method M --scene PATH [--preset P] [--set key=value ...] --out RUN_DIR`."""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

from gsbench import rundir
from gsbench.config import load_config, set_args
from gsbench.datasets.loader import SYNTHETIC_META
from gsbench.method_table import METHODS
from gsbench.outdir import check_run_folder
from gsbench.store import read_json

log = logging.getLogger(__name__)

#: presets whose schedules were tuned on the generated scenes, and the one tuned on real photos
SYNTHETIC_PRESETS = ("cpu-small", "cpu-medium")
REAL_PRESET = "cpu-real"


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


def preset_hint(preset: str | None, scene: Path) -> str | None:
    """The line `gsbench train` logs when a preset tuned on generated scenes meets a real capture (a
    scene folder without gsbench_scene.json): there it stops far short of convergence."""
    if preset not in SYNTHETIC_PRESETS or not scene.is_dir() or (scene / SYNTHETIC_META).exists():
        return None
    return (f"--preset {preset} is tuned for gsbench's generated scenes; on a real capture like {scene} it "
            f"stops well short of convergence: --preset {REAL_PRESET} trains four times as long for real photos "
            f"on a CPU (docs/real-captures.md)")


def run(args: argparse.Namespace) -> int:
    from gsbench.runs import train_run  # lazy: start-up (cli loads all commands)

    cfg = config_from_args(args)
    check_run_folder(args.out, args.scene)       # never into a folder of someone else's (gsbench.outdir)
    hint = preset_hint(args.preset, Path(args.scene))
    if hint:
        log.warning(hint)
    out = train_run(cfg, Path(args.scene), Path(args.out), progress=not args.no_progress)
    s = read_json(out / rundir.TRAIN_SUMMARY)
    ev = s.get("last_eval") or {}
    psnr = ev.get("psnr")
    print(f"gsbench train: {s['status']} {out} method={s['method']} iterations={s['iterations']} "
          f"gaussians={s['n_gaussians']} train_s={s['train_s']:.1f} peak_rss_mb={s['peak_rss_mb']:.0f} "
          f"backend={s['backend']}" + (f" test_psnr={psnr:.2f}" if psnr is not None else ""))
    return 0
