"""The `cpu` rasterizer's dynamic tile scheduling: an atomic counter and a costliest-first queue."""
import numba
import numpy as np
import pytest
import torch
from numba import njit, prange
from render_fields import look_at, random_field, with_grad

from gsbench.render import cpu_sched, render
from gsbench.render.cpu_sched import fetch_add, tile_queue


@njit(parallel=True, cache=False)
def _take_all(n_items, n_workers, counter, taken, by_worker):
    for w in prange(n_workers):
        while True:
            q = fetch_add(counter, 1)
            if q >= n_items:
                break
            taken[q] += 1          # each q is handed out once, so no two workers write one slot
            by_worker[w] += 1


@njit(cache=False)
def _serial(counter, steps):
    out = np.empty(steps.size, np.int64)
    for i in range(steps.size):
        out[i] = fetch_add(counter, steps[i])
    return out


def test_fetch_add_returns_the_old_value():
    counter = np.array([5], np.int64)
    old = _serial(counter, np.array([1, 3, -2, 0, 10], np.int64))
    assert old.tolist() == [5, 6, 9, 7, 7]
    assert counter[0] == 17


@pytest.mark.parametrize("n_workers", [1, 2, 7])
def test_every_item_is_taken_once_under_contention(n_workers):
    threads = numba.get_num_threads()
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    try:
        for n_items in (0, 1, 3, 20_000):
            counter = np.zeros(1, np.int64)
            taken = np.zeros(n_items, np.int64)
            by_worker = np.zeros(n_workers, np.int64)
            _take_all(n_items, n_workers, counter, taken, by_worker)
            assert (taken == 1).all()
            assert by_worker.sum() == n_items
            assert counter[0] == n_items + n_workers      # each worker's last take overshoots by one
    finally:
        numba.set_num_threads(threads)


def test_fetch_add_rejects_other_arrays():
    @njit
    def f(c):
        return fetch_add(c, 1)

    with pytest.raises(numba.core.errors.TypingError):
        f(np.zeros(1, np.int32))


def test_tile_queue_is_costliest_first_ties_by_index():
    tile_off = np.cumsum([0, 2, 5, 0, 5, 1, 3])         # pairs per tile: 2 5 0 5 1 3
    q = tile_queue(tile_off)
    assert q.dtype == np.int64
    assert q.tolist() == [1, 3, 5, 0, 4, 2]
    assert tile_queue(tile_off, 2, 5).tolist() == [3, 4, 2]   # tiles 2..4: pairs 0 5 1
    assert tile_queue(np.zeros(1, np.int64)).size == 0


def _render(field, cam):
    leaf = with_grad(field)
    out = render(leaf, cam, backend="cpu")
    g = torch.Generator().manual_seed(3)
    parts = (out.rgb, out.depth, out.alpha, out.features)
    (sum((p * torch.randn(p.shape, generator=g)).sum() for p in parts)).backward()
    return [p.detach() for p in parts], [t.grad for t in leaf.tensors().values()] + [out.means2d.grad]


@pytest.mark.parametrize("order", ["reversed", "shuffled"])
def test_the_order_tiles_are_taken_in_changes_nothing(monkeypatch, order):
    field = random_field(500, 7, d=3, scale=(0.02, 0.3), dtype=torch.float32)
    cam = look_at(80, 56, eye=(0.4, 0.3, -3.0))
    outs1, grads1 = _render(field, cam)
    rng = np.random.default_rng(0)

    def other_order(tile_off, t_lo=0, t_hi=None):
        q = tile_queue(tile_off, t_lo, t_hi)
        return q[::-1].copy() if order == "reversed" else rng.permutation(q)

    monkeypatch.setattr(cpu_sched, "tile_queue", other_order)
    outs2, grads2 = _render(field, cam)
    assert float(outs1[2].max()) > 0.5                  # the field is on screen
    for a, b in zip(outs1 + grads1, outs2 + grads2):
        assert torch.equal(a, b)
