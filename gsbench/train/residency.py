"""Where per-view training data lives: on the training device for the whole run (`train.data_on:
device`, the default), or in host memory with one view copied to the device when a step reads it
(`train.data_on: host`). At full resolution on a GPU the images and priors of every view can take
more memory than the Gaussians (docs/training.md#first-run-on-a-gpu); `host` trades that for one
host-to-device copy per step and view."""
from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import Any

import torch

from gsbench.config import setting
from gsbench.config_keys import DATA_PLACES as PLACES

DEVICE, HOST = PLACES


def _each(value: Any, fn: Callable[[torch.Tensor], torch.Tensor]) -> Any:
    """`fn` applied to a tensor, or to each tensor of a tuple (other items kept as they are)."""
    if torch.is_tensor(value):
        return fn(value)
    if isinstance(value, tuple):
        return tuple(_each(v, fn) for v in value)
    return value


def _to(value: Any, device: torch.device, non_blocking: bool = False) -> Any:
    """A tensor, or a tuple holding tensors, moved to `device`."""
    return _each(value, lambda t: t.to(device, non_blocking=non_blocking))


def _pin(value: Any) -> Any:
    """Page-locked host memory, so the per-step copy to a CUDA device can run asynchronously."""
    return _each(value, lambda t: t.pin_memory())


class HostViews(Mapping):
    """view id -> value held in host memory; reading an item returns it on `device`."""

    def __init__(self, host: dict, device: torch.device | str) -> None:
        self.device = torch.device(device)
        cpu = torch.device("cpu")
        self._pinned = self.device.type == "cuda"
        self._host = {k: (_pin(_to(v, cpu)) if self._pinned else _to(v, cpu)) for k, v in host.items()}

    def __getitem__(self, key: Any) -> Any:
        return _to(self._host[key], self.device, non_blocking=self._pinned)

    def __iter__(self) -> Iterator:
        return iter(self._host)

    def __len__(self) -> int:
        return len(self._host)

    def host_item(self, key: Any) -> Any:
        """The host copy itself (no device copy)."""
        return self._host[key]


def place(values: dict, device: torch.device | str, on: str) -> Mapping:
    """Per-view values for training: moved to `device` once (on="device") or kept on the host and moved
    per read (on="host")."""
    if on not in PLACES:
        raise ValueError(f"train.data_on must be one of {PLACES}, got {on!r}")
    if on == DEVICE:
        dev = torch.device(device)
        return {k: _to(v, dev) for k, v in values.items()}
    return HostViews(values, device)


def data_on(config: dict) -> str:
    """The run's `train.data_on`."""
    return str(setting(config, "train.data_on"))


__all__ = ["DEVICE", "HOST", "PLACES", "HostViews", "place", "data_on"]
