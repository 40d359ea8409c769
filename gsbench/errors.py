"""Errors a user can act on. The CLI prints them as one line and exits 1 (gsbench/cli.py).

`bounded_line` keeps that line short whatever the user gave: a name, path or value longer than
MAX_VALUE characters is cut in its middle (its start and its end are kept: the folder and the file
name), and the whole line is held to MAX_LINE characters."""
from __future__ import annotations

import re

MAX_VALUE = 200       # the most characters of one name, path or value an error line echoes
MAX_LINE = 1000       # the most characters of a whole error line
_LONG_WORD = re.compile(r"\S{%d,}" % (MAX_VALUE + 1))


class InputError(ValueError):
    """Bad input: the message names the file (or option) and what is wrong with it."""


class NonFiniteError(RuntimeError):
    """Training met a non-finite loss or parameter (the message says where and what to change)."""


class Terminated(KeyboardInterrupt):
    """SIGTERM during training (a scheduler or `kill` stopping the process): handled as Ctrl-C is, the
    run checkpointed and its status "interrupted"; the CLI exits 143 (128 + SIGTERM)."""


def interrupted(e: BaseException) -> bool:
    """Ctrl-C, also when it arrived during a compiled (numba) call: CPython then reports a SystemError
    ("... returned a result with an exception set") whose cause is the KeyboardInterrupt. The
    harness treats both as an interruption (status, exit code 130), not as a failure."""
    return isinstance(e, KeyboardInterrupt) or (isinstance(e, SystemError)
                                                and isinstance(e.__cause__, KeyboardInterrupt))


def shorten(value: object, limit: int = MAX_VALUE) -> str:
    """str(value) of at most `limit` characters: a longer one keeps its start and its end around
    "...", so a long path still shows its first folders and its file name."""
    text = str(value)
    if len(text) <= limit:
        return text
    head = (limit - 3) // 2
    return text[:head] + "..." + text[len(text) - (limit - 3 - head):]


def bounded_line(text: str) -> str:
    """An error message as one bounded line: lines joined with " | ", every run of more than
    MAX_VALUE non-blank characters (a path, a name, a value) shortened to MAX_VALUE, and the line
    cut to MAX_LINE characters (a long value with blanks in it)."""
    line = " | ".join(part.strip() for part in text.splitlines() if part.strip())
    line = _LONG_WORD.sub(lambda m: shorten(m.group(0)), line)
    return shorten(line, MAX_LINE)
