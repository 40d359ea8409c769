"""Dynamic scheduling of the `cpu` rasterizer's tiles: workers take the next tile from a shared counter.

numba's default threading layer here (`workqueue`, see gsbench/render/cpu_backend.py) splits a
prange statically: with two threads, the first takes the first half of the iterations and the
second the rest, whatever `numba.parallel_chunksize` says. The tiles of an image hold very
different numbers of Gaussians (an empty sky against a cluttered table), so a static split left
one core idle for much of every render. Instead the kernels run one prange iteration per thread,
and each iteration takes tiles from a list, costliest first, through an atomic counter
(`fetch_add`) until none is left: any threading layer then balances the work.

Which thread renders a tile does not change what it computes: every tile's pixels and gradient
rows are written by one task, in a fixed order, so outputs stay bit-identical for any thread count.
"""
from __future__ import annotations

import numpy as np
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def fetch_add(typingctx, counter, value):
    """Atomically add `value` to counter[0] (a 1-element int64 array) and return the old value."""
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64 and counter.ndim == 1):
        return None
    sig = types.int64(counter, types.int64)

    def codegen(context, builder, signature, args):
        arr = context.make_array(signature.args[0])(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, signature.args[0], arr,
                                       [context.get_constant(types.intp, 0)])
        return builder.atomic_rmw("add", ptr, args[1], "seq_cst")

    return sig, codegen


def tile_queue(tile_off: np.ndarray, t_lo: int = 0, t_hi: int | None = None) -> np.ndarray:
    """Tiles t_lo..t_hi - 1 (int64) in the order workers take them: most Gaussians first (ties by
    index), so the last tiles taken are the cheap ones and no worker is left with a long one."""
    t_hi = tile_off.size - 1 if t_hi is None else t_hi
    cost = np.diff(tile_off[t_lo:t_hi + 1]).astype(np.int64)
    return np.argsort(-cost, kind="stable").astype(np.int64) + t_lo
