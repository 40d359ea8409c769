"""gsbench.methods: the Method protocol and the methods behind it (see base.py).

    get_method("gaussiands" | "vanilla" | "twostage") -> Method class
"""
from __future__ import annotations

from gsbench.methods.base import Method

METHODS = ("gaussiands", "vanilla", "twostage")


def get_method(name: str) -> type[Method]:
    """The Method class registered under `name`."""
    if name == "gaussiands":
        from gsbench.methods.gaussiands import GaussianDS
        return GaussianDS
    if name == "vanilla":
        from gsbench.methods.vanilla import Vanilla
        return Vanilla
    if name == "twostage":
        from gsbench.methods.twostage import TwoStage
        return TwoStage
    raise ValueError(f"unknown method {name!r}; choose one of {', '.join(METHODS)}")


__all__ = ["Method", "get_method", "METHODS"]
