"""Logging is configured once by the CLI; process-wide settings are made once by gsbench.startup()."""
from __future__ import annotations

import logging

import pytest
import torch

import gsbench
from gsbench.cli import apply_global_flags, build_parser, configure_logging


@pytest.fixture
def restore_gsbench_logger():
    logger = logging.getLogger("gsbench")
    saved = (list(logger.handlers), logger.level, logger.propagate)
    yield logger
    logger.handlers[:], logger.level, logger.propagate = saved[0], saved[1], saved[2]


# ---------------------------------------------------------------------------- start-up settings
def test_startup_sets_the_process_settings_once(monkeypatch):
    calls = []
    monkeypatch.setattr(torch, "set_flush_denormal", lambda on: calls.append(on) or True)
    monkeypatch.setattr(gsbench, "_STARTED", False)
    monkeypatch.delenv("GOMP_SPINCOUNT", raising=False)
    gsbench.startup()
    gsbench.startup()
    assert calls == [True]
    import os
    assert os.environ["GOMP_SPINCOUNT"] == "0"


def test_startup_keeps_a_spincount_the_user_set(monkeypatch):
    monkeypatch.setattr(torch, "set_flush_denormal", lambda on: True)
    monkeypatch.setattr(gsbench, "_STARTED", False)
    monkeypatch.setenv("GOMP_SPINCOUNT", "7")
    gsbench.startup()
    import os
    assert os.environ["GOMP_SPINCOUNT"] == "7"


def test_importing_gsbench_flushed_denormals():
    # 1e-323 is a float64 denormal: read as 0 once flush-denormal is on (x86 with SSE3)
    if not torch.set_flush_denormal(True):
        pytest.skip("this CPU cannot flush denormals")
    assert float(torch.tensor([1e-323], dtype=torch.float64)[0]) == 0.0


@pytest.mark.parametrize("backend", ["torch", "cpu"])
def test_render_does_not_touch_process_state(backend, monkeypatch):
    import numpy as np

    from gsbench.camera import Camera
    from gsbench.gaussians import GaussianField
    from gsbench.render import render
    calls = []
    monkeypatch.setattr(torch, "set_flush_denormal", lambda on: calls.append(on) or True)
    K = np.array([[20.0, 0, 8], [0, 20.0, 6], [0, 0, 1]])
    cam = Camera(K, np.eye(4), 16, 12)
    n = 5
    fld = GaussianField(torch.tensor([[0.0, 0.0, 3.0]]).repeat(n, 1) + torch.randn(n, 3) * 0.1,
                        torch.full((n, 3), -2.0), torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
                        torch.zeros(n), torch.rand(n, 3), None)
    for _ in range(2):
        out = render(fld, cam, backend=backend)
    assert out.rgb.shape == (12, 16, 3)
    assert calls == []


# ---------------------------------------------------------------------------- logging
def test_log_level_from_quiet_and_verbose(restore_gsbench_logger):
    assert configure_logging() == logging.INFO
    assert configure_logging(quiet=True) == logging.WARNING
    assert configure_logging(verbose=True) == logging.DEBUG
    cli_handlers = [h for h in restore_gsbench_logger.handlers if getattr(h, "_gsbench_cli", False)]
    assert len(cli_handlers) == 1          # replaced, not stacked, when configured again


def test_library_messages_reach_stderr_unless_quiet(restore_gsbench_logger, capsys):
    log = logging.getLogger("gsbench.some.module")
    configure_logging()
    log.info("dropped priors.depth")
    assert "gsbench: dropped priors.depth" in capsys.readouterr().err
    configure_logging(quiet=True)
    log.info("not shown")
    log.warning("shown")
    err = capsys.readouterr().err
    assert "not shown" not in err and "shown" in err


@pytest.mark.parametrize("where", ["before", "after"])
def test_global_flags_before_or_after_the_command(where, restore_gsbench_logger):
    flags = ["--quiet", "--debug"]
    cmd = ["make-scene", "--preset", "tabletop-small", "--out", "X"]
    argv = flags + cmd if where == "before" else cmd + flags
    args = apply_global_flags(build_parser().parse_args(argv))
    assert args.quiet and args.debug and args.no_progress
    assert restore_gsbench_logger.level == logging.WARNING


def test_quiet_and_verbose_exclude_each_other():
    with pytest.raises(SystemExit):
        build_parser().parse_args(["train", "-q", "-v"])


def test_one_flag_name_per_meaning():
    """Progress bars go off with --no-progress on every command that has them; no command has its
    own --quiet (the global one sets the log level and turns bars off too)."""
    parser = build_parser()
    subs = parser._subparsers._group_actions[0].choices
    for name, sub in subs.items():
        opts = {o for a in sub._actions for o in a.option_strings}
        for bad in ("--no-progress-bar", "--silent", "--no-bar", "--progress"):
            assert bad not in opts, (name, bad)
        quiet = [a for a in sub._actions if "--quiet" in a.option_strings]
        assert len(quiet) == 1 and quiet[0].help.startswith("warnings and errors only"), name
    for name in ("make-scene", "train", "eval", "ablate", "report"):
        assert "--no-progress" in {o for a in subs[name]._actions for o in a.option_strings}, name
