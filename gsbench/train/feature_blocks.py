"""A rendered feature map handed out in blocks of pixel rows, computed as they are asked for.

Evaluation scores the decode query mode from 512-d features per pixel: 100 MB at 256x192, 3.2 GB
at 1440x1080. Decoding and scoring a block of pixels at a time keeps each block in the cache and
never holds the whole decoded map; the values are those of the whole map (the decoder and the
cosines treat each pixel on its own, and the blocks have fixed boundaries).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterator, Optional

import torch

# pixels per block: a 4096 x 512 float32 layer output (8 MB) stays in the cache for the ReLU and
# normalisation passes; a 256x192 map in one piece decoded ~1.5x slower, with the same bits (rows are
# independent in the matrix products; tests/methods/test_methods.py checks it at the real sizes)
BLOCK_ROWS = 4096


@dataclass(frozen=True)
class FeatureBlocks:
    """An (height, width, D) feature map as blocks of pixels in row-major order; `blocks()` starts a
    new pass and may compute each block on the fly."""

    height: int
    width: int
    blocks: Callable[[], Iterator[torch.Tensor]]

    @staticmethod
    def of_map(features: torch.Tensor, fn: Optional[Callable[[torch.Tensor], torch.Tensor]] = None,
               rows: Optional[int] = None) -> "FeatureBlocks":
        """Blocks of `rows` pixels (default BLOCK_ROWS; fn None: one block, the map itself) of an
        (H, W, d) map, each passed through fn (rows (n, d) -> (n, D)) when one is given."""
        h, w, d = features.shape
        flat = features.reshape(-1, d)
        step = flat.shape[0] if fn is None and rows is None else max(1, int(rows or BLOCK_ROWS))

        def blocks() -> Iterator[torch.Tensor]:
            for k in range(0, flat.shape[0], step):
                b = flat[k:k + step]
                yield b if fn is None else fn(b)
        return FeatureBlocks(h, w, blocks)

    def join(self) -> torch.Tensor:
        """The whole (height, width, D) map."""
        parts = self.blocks()
        first = next(parts)
        n = self.height * self.width
        if first.shape[0] == n:
            return first.reshape(self.height, self.width, -1)
        out = torch.empty(n, first.shape[1], dtype=first.dtype, device=first.device)
        out[:first.shape[0]] = first
        k = first.shape[0]
        for b in parts:
            out[k:k + b.shape[0]] = b
            k += b.shape[0]
        return out.reshape(self.height, self.width, -1)
