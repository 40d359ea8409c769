"""A trainer whose render fails at a chosen call: the tests of interrupted and failed runs."""
from __future__ import annotations

import gsbench.train.trainer as T


def fail_render_at(monkeypatch, call: int, error: BaseException):
    """Make the trainer's `render` raise `error` at its `call`-th call (1-based); returns the real
    render, for a test that puts it back to resume."""
    real, calls = T.render, {"n": 0}

    def render(*a, **k):
        calls["n"] += 1
        if calls["n"] == call:
            raise error
        return real(*a, **k)
    monkeypatch.setattr(T, "render", render)
    return real
