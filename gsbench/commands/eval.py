"""`gsbench eval`."""
from __future__ import annotations

import argparse

from gsbench.errors import NotBuiltError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    pass


def run(args: argparse.Namespace) -> int:
    raise NotBuiltError("`gsbench eval` is not implemented in this build")
