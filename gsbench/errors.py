"""Errors a user can act on. The CLI prints them as one line and exits 1 (gsbench/cli.py)."""


class InputError(ValueError):
    """Bad input: the message names the file (or option) and what is wrong with it."""


class NonFiniteError(RuntimeError):
    """Training met a non-finite loss or parameter (the message says where and what to change)."""
