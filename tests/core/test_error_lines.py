"""No error line echoes an unbounded user value: the CLI prints every one-line error through
gsbench.errors.bounded_line, which cuts each name, path or value to MAX_VALUE characters (keeping
its start and end) and the line to MAX_LINE; argparse's usage errors too."""
from __future__ import annotations

import os

import pytest

from gsbench.cli import main, one_line
from gsbench.errors import MAX_LINE, MAX_VALUE, InputError, bounded_line, shorten

LONG = "/data/" + "a" * 10_000 + "/scene.png"


def test_a_long_value_keeps_its_start_and_end():
    s = shorten(LONG)
    assert len(s) == MAX_VALUE == 200
    assert s.startswith("/data/aaa") and s.endswith("aaa/scene.png") and "..." in s
    assert shorten("short") == "short"


def test_every_long_word_of_a_message_is_cut_and_short_ones_stay():
    line = bounded_line(f"{LONG}: image is 2x3, camera says {LONG}")
    assert len(line) < 2 * MAX_VALUE + 40
    assert ": image is 2x3, camera says " in line and line.count("/scene.png") == 2


def test_a_long_value_with_blanks_is_held_to_the_line_budget():
    line = bounded_line("x: " + "word " * 5000)
    assert len(line) == MAX_LINE


def test_multi_line_messages_become_one_line():
    assert bounded_line("first\n  second\n\nthird") == "first | second | third"


def test_os_errors_name_a_shortened_file():
    e = OSError(36, "File name too long", LONG)
    line = one_line(e)
    assert line.endswith(": File name too long") and len(line) <= MAX_VALUE + 30


@pytest.mark.parametrize("argv", [
    ["eval", LONG],
    ["data", "check", LONG],
    ["train", "--method", "vanilla", "--scene", LONG, "--out", LONG],
    ["train", "--method", "vanilla", "--scene", LONG, "--out", "run"],
    ["report", LONG, "--out", LONG],
])
def test_cli_error_lines_with_a_10000_character_path_are_bounded(argv, capsys, tmp_path):
    os.chdir(tmp_path)
    code = main(argv)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 1 and lines[-1].startswith(f"gsbench {argv[0]}: error: ")
    assert len(lines[-1]) <= MAX_LINE and "a" * (MAX_VALUE + 1) not in lines[-1], lines[-1][:500]
    assert len(lines[-1]) < 200 + len(argv) * MAX_VALUE     # the message, and each long value once at most


def test_an_invalid_choice_is_bounded_too(capsys):
    with pytest.raises(SystemExit) as e:
        main(["train", "--method", "m" * 10_000, "--scene", "s", "--out", "o"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "m" * (MAX_VALUE + 1) not in err and len(err.splitlines()[-1]) <= 400


def test_input_errors_raised_anywhere_go_through_it(monkeypatch, capsys):
    import gsbench.commands.eval as ev

    def boom(args):
        raise InputError(f"{LONG}: bad")
    monkeypatch.setattr(ev, "run", boom)
    assert main(["eval", "x"]) == 1
    last = capsys.readouterr().err.splitlines()[-1]
    assert last.endswith("/scene.png: bad") and len(last) < 260
