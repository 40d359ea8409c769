"""The command line: sub-commands, one-line user errors, tracebacks for bugs and with --debug."""
import subprocess
import sys

import pytest

from gsbench import cli
from gsbench.errors import InputError


def test_help_lists_subcommands():
    out = subprocess.run(
        [sys.executable, "-m", "gsbench.cli", "--help"], capture_output=True, text=True, check=True
    ).stdout
    for cmd in ["make-scene", "train", "eval", "ablate", "report", "stress"]:
        assert cmd in out


# ---------------------------------------------------------------------------- errors
def _raising(monkeypatch, exc: BaseException):
    import gsbench.commands.collect as C

    def run(args):
        raise exc
    monkeypatch.setattr(C, "run", run)


def test_input_error_is_one_line_and_exit_1(monkeypatch, capsys, tmp_path):
    monkeypatch.delenv("GSBENCH_DEBUG", raising=False)
    _raising(monkeypatch, InputError("results.json: corrupt\nsecond line"))
    assert cli.main(["collect", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert err == "gsbench collect: error: results.json: corrupt | second line\n"


def test_os_error_names_the_path(monkeypatch, capsys, tmp_path):
    monkeypatch.delenv("GSBENCH_DEBUG", raising=False)
    _raising(monkeypatch, PermissionError(13, "Permission denied", "/x/runs"))
    assert cli.main(["collect", str(tmp_path)]) == 1
    assert "/x/runs: Permission denied (not writable/readable by this user)" in capsys.readouterr().err


@pytest.mark.parametrize("exc", [ValueError("internal bug"), KeyError("k"), RuntimeError("boom")])
def test_internal_errors_propagate_with_their_traceback(exc, monkeypatch, tmp_path):
    monkeypatch.delenv("GSBENCH_DEBUG", raising=False)
    _raising(monkeypatch, exc)
    with pytest.raises(type(exc)):
        cli.main(["collect", str(tmp_path)])


@pytest.mark.parametrize("how", ["flag-before", "flag-after", "env"])
def test_debug_shows_the_traceback_of_input_errors(how, monkeypatch, tmp_path):
    monkeypatch.delenv("GSBENCH_DEBUG", raising=False)
    _raising(monkeypatch, InputError("bad file"))
    argv = ["collect", str(tmp_path)]
    if how == "flag-before":
        argv = ["--debug"] + argv
    elif how == "flag-after":
        argv = argv + ["--debug"]
    else:
        monkeypatch.setenv("GSBENCH_DEBUG", "1")
    with pytest.raises(InputError, match="bad file"):
        cli.main(argv)


def test_debug_env_zero_is_off(monkeypatch, tmp_path):
    monkeypatch.setenv("GSBENCH_DEBUG", "0")
    _raising(monkeypatch, InputError("bad file"))
    assert cli.main(["collect", str(tmp_path)]) == 1


def test_a_real_bad_input_exits_1_without_traceback(tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "results.json").write_text('{"metrics": ')
    p = subprocess.run([sys.executable, "-m", "gsbench.cli", "collect", str(tmp_path)], capture_output=True, text=True)
    assert p.returncode == 1, p.stderr
    assert "Traceback" not in p.stderr and "results.json" in p.stderr and "corrupt or truncated JSON" in p.stderr
    p = subprocess.run(
        [sys.executable, "-m", "gsbench.cli", "--debug", "collect", str(tmp_path)], capture_output=True, text=True
    )
    assert p.returncode == 1 and "Traceback" in p.stderr and "InputError" in p.stderr
