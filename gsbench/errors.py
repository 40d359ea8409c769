"""Errors a user can act on. The CLI prints them as one line and exits non-zero."""


class InputError(ValueError):
    """Bad input: the message names the file (or option) and what is wrong with it."""


class NotBuiltError(RuntimeError):
    """A stage of the pipeline that does not exist yet; never replaced by a fake result."""


class NonFiniteError(RuntimeError):
    """Training met a non-finite loss or parameter."""
