"""Errors a user can act on. The CLI prints them as one line and exits 1 (gsbench/cli.py)."""


class InputError(ValueError):
    """Bad input: the message names the file (or option) and what is wrong with it."""


class NonFiniteError(RuntimeError):
    """Training met a non-finite loss or parameter (the message says where and what to change)."""


def interrupted(e: BaseException) -> bool:
    """Ctrl-C, also when it arrived during a compiled (numba) call: CPython then reports a SystemError
    ("... returned a result with an exception set") whose cause is the KeyboardInterrupt. The
    harness treats both as an interruption (status, exit code 130), not as a failure."""
    return isinstance(e, KeyboardInterrupt) or (isinstance(e, SystemError)
                                                and isinstance(e.__cause__, KeyboardInterrupt))
