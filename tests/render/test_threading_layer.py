"""numba's threading layer (gsbench/render/threads.py): tbb where the tbb package loads, else
workqueue, unless NUMBA_THREADING_LAYER says otherwise; and the cpu backend's outputs and gradients
are the same bits on both layers (each runs in its own process: the layer is fixed at first use)."""
from __future__ import annotations

import importlib.metadata
import os
import subprocess
import sys

import numpy as np
import pytest

from gsbench.render import threads

_RENDER = r"""
import sys, numpy as np, torch, numba
import gsbench
from gsbench.camera import Camera
from gsbench.gaussians import GaussianField
from gsbench.render import render
torch.set_num_threads(2)
g = torch.Generator().manual_seed(0)
n = 3000
means = torch.cat([torch.rand(n, 2, generator=g) * 4 - 2, torch.rand(n, 1, generator=g) * 4 + 2], 1)
leaves = [means, torch.rand(n, 3, generator=g) * 2 - 4.5, torch.randn(n, 4, generator=g),
          torch.randn(n, generator=g), torch.rand(n, 1, 3, generator=g), torch.rand(n, 3, generator=g)]
leaves = [t.requires_grad_(True) for t in leaves]
cam = Camera(np.array([[80.0, 0, 48], [0, 80.0, 32], [0, 0, 1]]), np.eye(4), 96, 64)
out = render(GaussianField(*leaves), cam, backend="cpu")
(out.rgb.square().mean() + out.depth.mean() + out.features.mean() + out.alpha.mean()).backward()
arrays = [out.rgb, out.depth, out.features, out.alpha] + [t.grad for t in leaves]
np.savez(sys.argv[1], *[a.detach().numpy() for a in arrays])
print(numba.threading_layer())
"""


def _render_in(layer: str, out) -> str:
    env = {**os.environ, "NUMBA_THREADING_LAYER": layer, "GSBENCH_THREADS": "2"}
    res = subprocess.run([sys.executable, "-c", _RENDER, str(out)], capture_output=True, text=True, env=env,
                         timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    return res.stdout.strip().splitlines()[-1]


@pytest.mark.skipif(threads._load_tbb() is False, reason="the tbb package is not installed here")
def test_tbb_and_workqueue_render_the_same_bits(tmp_path):
    assert _render_in("workqueue", tmp_path / "wq.npz") == "workqueue"
    assert _render_in("tbb", tmp_path / "tbb.npz") == "tbb"
    a, b = np.load(tmp_path / "wq.npz"), np.load(tmp_path / "tbb.npz")
    assert len(a.files) == 10 and np.any(a["arr_4"] != 0)
    for k in a.files:
        assert np.array_equal(a[k], b[k]), k


def test_the_layer_is_the_users_then_tbb_then_workqueue(monkeypatch):
    monkeypatch.setattr(threads, "_chosen", None)
    monkeypatch.setenv("NUMBA_THREADING_LAYER", "omp")
    assert threads.select_numba_threading_layer() == "omp"          # the user's choice stands
    monkeypatch.delenv("NUMBA_THREADING_LAYER")
    monkeypatch.setattr(threads, "_load_tbb", lambda: True)
    assert threads.select_numba_threading_layer() == "tbb" and os.environ["NUMBA_THREADING_LAYER"] == "tbb"
    monkeypatch.delenv("NUMBA_THREADING_LAYER")
    monkeypatch.setattr(threads, "_load_tbb", lambda: False)
    assert threads.select_numba_threading_layer() == "workqueue"
    assert threads.numba_threading_layer() == "workqueue"


def test_no_tbb_package_means_no_tbb(monkeypatch):
    def missing(name):
        raise importlib.metadata.PackageNotFoundError(name)
    monkeypatch.setattr(importlib.metadata, "distribution", missing)
    assert threads._load_tbb() is False


def test_a_tbb_numba_cannot_load_falls_back_only_when_gsbench_chose_it(monkeypatch):
    monkeypatch.setattr(threads, "_chosen", None)
    monkeypatch.delenv("NUMBA_THREADING_LAYER", raising=False)
    monkeypatch.setattr(threads, "_load_tbb", lambda: True)
    assert threads.select_numba_threading_layer() == "tbb"
    assert threads.tbb_unusable(ImportError("tbbpool")) == "workqueue"
    assert os.environ["NUMBA_THREADING_LAYER"] == "workqueue"
    monkeypatch.setenv("NUMBA_THREADING_LAYER", "tbb")         # the user's choice: numba's error stands
    assert threads.select_numba_threading_layer() == "tbb"
    with pytest.raises(ImportError, match="tbbpool"):
        threads.tbb_unusable(ImportError("tbbpool"))
