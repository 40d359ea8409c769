"""A CPU training run gives the same bits whatever its thread budget: the trainer runs a step's
PyTorch ops on one thread and the cpu backend's kernels on the budget (gsbench/render/threads.py),
whose results do not depend on the thread count. Before, PyTorch's parallel reductions and matrix
products split by the thread count, and grouping's log differed between 1 and 2 threads."""
from __future__ import annotations

import pytest
import torch
from tiny import TINY_SET

from gsbench.config import load_config
from gsbench.render.threads import kernel_threads, numba_threading_layer, torch_ops_serial
from gsbench.runs import train_run
from gsbench.store import read_json, read_jsonl


def _run(scene, out, method, threads, monkeypatch):
    monkeypatch.setenv("GSBENCH_THREADS", str(threads))
    run = train_run(load_config(method, "cpu-small", [*TINY_SET, "train.densify.until_iter=20"]), scene, out,
                    progress=False)
    log = [{k: v for k, v in r.items() if k != "wall_s"} for r in read_jsonl(run / "train_log.jsonl")]
    # the run records numba's threading layer (speed only: the kernels give the same bits on each)
    assert read_json(run / "train_summary.json")["numba_threading_layer"] == numba_threading_layer()
    return log, torch.load(run / "checkpoint.pt", weights_only=False)["params"]


@pytest.mark.parametrize("method", ["grouping", "gaussiands"])
def test_one_and_two_threads_train_the_same_bits(tiny_scene, tmp_path, monkeypatch, method):
    log1, p1 = _run(tiny_scene, tmp_path / "t1", method, 1, monkeypatch)
    log2, p2 = _run(tiny_scene, tmp_path / "t2", method, 2, monkeypatch)
    assert log1 == log2 and len(log1) >= 4
    assert p1.keys() == p2.keys()
    for k in p1:
        assert torch.equal(p1[k], p2[k]), k


def test_the_serial_block_keeps_the_kernels_threads_and_restores_torchs():
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        with torch_ops_serial():
            assert torch.get_num_threads() == 1 and kernel_threads() == 2
            with torch_ops_serial():          # nested: the budget stays the outer one's
                assert torch.get_num_threads() == 1 and kernel_threads() == 2
        assert torch.get_num_threads() == 2 and kernel_threads() == 2
        with pytest.raises(RuntimeError), torch_ops_serial():
            raise RuntimeError("a failing step")
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
