"""Comparing label maps up to a renaming of their ids."""
from __future__ import annotations

import numpy as np


def same_partition(a, b):
    """True when two label maps split the pixels identically (ids may differ)."""
    if not np.array_equal(a < 0, b < 0):
        return False
    pairs = np.unique(np.stack([a[a >= 0], b[b >= 0]], 1), axis=0)
    return len(pairs) == len(np.unique(a[a >= 0])) == len(np.unique(b[b >= 0]))
