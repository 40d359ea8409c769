"""`gsbench data check PATH`: read a dataset folder as the evaluation would and list every problem."""
from __future__ import annotations

import argparse

from gsbench.datasets.check import check_folder


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="data_command", metavar="SUBCOMMAND", required=True)
    p = sub.add_parser("check", help="print a scene folder's layout, views, labels and every problem (exit 1 on any)",
                       description="Read a scene folder as training and evaluation would: the layout, views, "
                                   "resolution, labelled frames, classes or queries, poses and points, and every "
                                   "problem on one line naming its file. Exit status 1 when there is a problem.")
    p.add_argument("path", help="scene folder")
    p.add_argument("--layout", default="auto", help="layout to read it as: a registered layout's name "
                   "(colmap, llff, nerf, 3dovs, lerf, 3dovs+lerf, kaolin, or a plugin's; default: auto, detected)")


def run(args: argparse.Namespace) -> int:
    rep = check_folder(args.path, args.layout)
    print("\n".join(rep.lines()))
    return 0 if rep.ok else 1
