"""Ctrl-C that lands inside a compiled (numba) call reaches Python as a SystemError ("... returned a
result with an exception set") caused by the KeyboardInterrupt. The harness treats it as an
interruption: the run's status says interrupted, KeyboardInterrupt propagates and the CLI exits 130;
any other SystemError stays a failure."""
from __future__ import annotations

import pytest
from render_faults import fail_render_at
from tiny import TINY_SET

from gsbench import cli
from gsbench.config import load_config
from gsbench.errors import interrupted
from gsbench.runs import train_run
from gsbench.store import read_json


def _kernel_error(cause: BaseException | None) -> SystemError:
    try:
        raise SystemError("CPUDispatcher(<function bin_tiles>) returned a result with an exception set") from cause
    except SystemError as e:
        return e


def test_ctrl_c_inside_a_kernel_is_an_interruption(tiny_scene, tmp_path, monkeypatch):
    assert interrupted(_kernel_error(KeyboardInterrupt())) and interrupted(KeyboardInterrupt())
    assert not interrupted(_kernel_error(ValueError("x"))) and not interrupted(_kernel_error(None))
    fail_render_at(monkeypatch, 3, _kernel_error(KeyboardInterrupt()))
    with pytest.raises(KeyboardInterrupt):
        train_run(load_config("vanilla", "cpu-small", TINY_SET), tiny_scene, tmp_path / "run", progress=False)
    st = read_json(tmp_path / "run" / "status.json")
    assert st["state"] == "interrupted" and "interrupted" in st["message"]


def test_another_system_error_stays_a_failure(tiny_scene, tmp_path, monkeypatch):
    fail_render_at(monkeypatch, 3, _kernel_error(None))
    with pytest.raises(SystemError):
        train_run(load_config("vanilla", "cpu-small", TINY_SET), tiny_scene, tmp_path / "run", progress=False)
    assert "SystemError" in read_json(tmp_path / "run" / "status.json")["message"]


def test_the_cli_exits_130(tiny_scene, tmp_path, monkeypatch, capsys):
    fail_render_at(monkeypatch, 3, _kernel_error(KeyboardInterrupt()))
    rc = cli.main(["train", "--method", "vanilla", "--preset", "cpu-small", "--scene", str(tiny_scene),
                   "--out", str(tmp_path / "run"), "--no-progress", *[a for s in TINY_SET for a in ("--set", s)]])
    assert rc == 130 and "interrupted" in capsys.readouterr().err
