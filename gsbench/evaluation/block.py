"""What each evaluation step returns: its metrics with ids, per-view values and reasons.

Steps return a Block instead of filling shared dicts, so each one can be read and tested alone;
`merge` joins them in evaluate_run.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np

from gsbench.results import summarise


@dataclass
class Block:
    metrics: dict = field(default_factory=dict)
    metric_impl: dict = field(default_factory=dict)
    per_view: dict = field(default_factory=dict)
    skipped: dict = field(default_factory=dict)     # metric name -> reason
    notes: dict = field(default_factory=dict)       # topic -> text (not a metric)
    frames: dict = field(default_factory=dict)      # frame set -> [frame names]
    resolution: dict = field(default_factory=dict)  # frame set -> "WxH"
    timings: dict = field(default_factory=dict)

    def put(self, name: str, value: Optional[float], impl: Optional[str], reason: Optional[str] = None,
            per_view: Optional[list] = None) -> None:
        """One metric: its value and id, or None and the reason (never None without one)."""
        self.metrics[name] = value
        if impl is not None:
            self.metric_impl[name] = impl
        if per_view is not None:
            self.per_view[name] = per_view
        if value is None:
            self.skipped[name] = reason or "not computed (no reason given)"

    def put_mean(self, name: str, values: list, impl: str, names: Optional[list] = None) -> None:
        """Mean of per-view values; None with the count of missing views when any is missing."""
        mean, reason = summarise(values, names)
        self.put(name, mean, impl, reason, per_view=values)

    def skip(self, names, reason: str) -> None:
        for n in names:
            self.put(n, None, None, reason)

    def merge(self, other: "Block") -> "Block":
        for k in ("metrics", "metric_impl", "per_view", "skipped", "notes", "frames", "resolution", "timings"):
            getattr(self, k).update(getattr(other, k))
        return self


def to_numpy(x: Any) -> np.ndarray:
    """A render output as float numpy (the method keeps its tensors on its own device)."""
    import torch
    if isinstance(x, torch.Tensor):
        return x.detach().float().cpu().numpy()
    return np.asarray(x)
