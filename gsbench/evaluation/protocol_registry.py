"""The registry of evaluation protocols: each protocol is one file, as each method is (docs/protocols.md).

A protocol file is a module of gsbench.evaluation named `<anything>_protocol` that holds `PROTOCOL`, an
instance of a `Protocol` subclass: its name, its metric names, its frames, its resolution rule, its
scoring and its named forks (scoring variants, the first the default). The registry finds those modules
on first use (no list of built-ins to keep), then the entry points of the `gsbench.protocols` group, so
an installed package adds a protocol the same way:

    [project.entry-points."gsbench.protocols"]
    mine = "my_package.mine_protocol:PROTOCOL"

`register(protocol)` is the hook for code that builds a protocol at run time (tests). Registering a
protocol also enters its metric names in the ground-floor metric table
(`gsbench.metric_table.add_segmentation_protocol`), so results.json accepts them.

A request (`gsbench eval --protocol`) is "auto" (every protocol the scene supports, each under its
default fork) or a comma-separated list of protocol and fork names: `3dovs` is the 3D-OVS protocol
under its default fork, `3dovs-threshold` the same protocol under that fork.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Optional

from gsbench.camera import training_size
from gsbench.config import setting
from gsbench.errors import InputError
from gsbench.metric_table import add_segmentation_protocol, seg_metric
from gsbench.plugin_registry import PluginRegistry

from .block import Block

log = logging.getLogger(__name__)

PROTOCOLS_PACKAGE = "gsbench.evaluation"   # where the built-in `*_protocol` modules live
ENTRY_POINT_GROUP = "gsbench.protocols"
AUTO = "auto"


class Protocol:
    """One evaluation protocol. Subclass it, set the class attributes, override what differs."""

    name: str = ""                       # the --protocol value and the results.json `protocols` entry
    metric_key: str = ""                 # metric names f"{base}_{metric_key}"; default: name without '-'
    metrics: tuple[str, ...] = ()        # the metric bases it writes
    forks: tuple[str, ...] = ()          # named scoring variants; forks[0] is the default
    order: int = 100                     # order among protocols (3dovs 10, lerf 20)
    renders_frames: bool = False         # scores rendered frames (the frame hooks below); the trainer's
    #                                      periodic evaluation scores only such protocols
    in_auto: bool = True                 # part of the `auto` request; False: run only when named (a
    #                                      protocol added after cells were published, whose metrics they lack)

    @property
    def key(self) -> str:
        return self.metric_key or self.name.replace("-", "")

    @property
    def default_fork(self) -> str:
        return self.forks[0] if self.forks else ""

    def supports(self, scene) -> Optional[str]:
        """None when the scene can be scored, else the reason."""
        return None

    def frames(self, scene) -> list[int]:
        """The labelled view ids this protocol scores ([]: a protocol without frames)."""
        return []

    def camera(self, scene, i: int, config: dict):
        """The camera view i is scored at (default: the training size)."""
        cam = scene.cameras[i]
        w, h = training_size(cam, setting(config, "train.max_width"))
        return cam if (w, h) == (cam.width, cam.height) else cam.resized(w, h)

    def score(self, ctx: "ProtocolContext") -> Block:
        """Every number of the protocol, over ctx.sets and ctx.modes."""
        raise NotImplementedError(f"protocol {self.name!r} has no score()")

    # optional hooks, used by the frame-based built-ins -------------------------------------------
    def frame_query(self, scene, i: int, cam, fork: str) -> Any:
        """What the protocol needs of frame i at camera `cam` besides its features (e.g. its GT labels),
        read once per frame; passed to `frame_texts` and `frame_output`."""
        return None

    def frame_texts(self, context: Any, embed, fork: str) -> Any:
        """The (K, D) texts whose cosines with the frame's rendered features the evaluation computes (once
        for every protocol, a block of pixels at a time), or None; embed(list of texts) -> (K, D) or None
        in the query mode being scored."""
        return None

    def frame_output(self, cosines, context: Any, cam, fork: str) -> Any:
        """The per-frame result kept from the (H*W, K) cosines (None: the method gave no features)."""
        return None

    def preview(self, scene, i: int, cam, config: dict, mode: str, value: Any) -> Optional[tuple]:
        """(queries, predicted masks, GT masks, metric impl) of frame i for the pictures, or None."""
        return None

    def score_folder(self, pred_dir, layout_dir, ratio: float) -> tuple[Block, dict]:
        """A folder of predicted masks scored (`gsbench eval --masks`)."""
        raise InputError(f"protocol {self.name} does not score mask folders")

    def metric_name(self, base: str, mode: Optional[str] = None, frame_set: str = "reference") -> str:
        return seg_metric(base, self.name, mode, frame_set)

    def plain_names(self) -> list[str]:
        """Its metric names without a mode or frame-set suffix."""
        return [self.metric_name(b) for b in self.metrics]


@dataclass
class ProtocolContext:
    """What a protocol's `score` receives (docs/protocols.md, "Adding a protocol")."""

    protocol: Protocol
    method: Any
    scene: Any
    config: dict
    sets: dict                            # {"reference": [view ids], "held-out": [view ids]}
    modes: tuple
    configured: str                       # query.mode: the un-suffixed names carry it
    fork: str = ""
    frames: dict = field(default_factory=dict)   # render-once cache {(protocol, mode, view id): frame output}

    def names(self, base: str, mode: str, frame_set: str = "reference") -> list[str]:
        """The names one (base, mode, frame set) value is stored under."""
        out = [self.protocol.metric_name(base, mode, frame_set)]
        if mode == self.configured:
            out.append(self.protocol.metric_name(base, None, frame_set))
        return out

    def fork_tag(self) -> str:
        """"" under the default fork, else "+fork-<name>" (appended to the metric ids)."""
        return "" if self.fork == self.protocol.default_fork else f"+fork-{self.fork}"


def _admit(protocol: Any, where: str) -> None:
    """The checks before a protocol is entered; its metric names go into the metric table."""
    if not isinstance(protocol, Protocol):
        raise InputError(f"{where}: names {type(protocol).__name__}, not a gsbench Protocol")
    name = protocol.name
    if not name or not name.replace("-", "").replace("_", "").isalnum() or name == AUTO:
        raise InputError(f"{where}: protocol name {name!r}: use letters, digits, '-' or '_' (not 'auto')")
    if not protocol.metrics:
        raise InputError(f"{where}: protocol {name!r} declares no metric names")
    taken = {n: p for p in _TABLE.items.values() for n in (p.name, *p.forks)}
    for n in (name, *protocol.forks):
        if n in taken and not (n == name and taken[n] is protocol):
            raise InputError(f"{where}: name {n!r} is already taken by protocol {taken[n].name!r}")
    try:
        add_segmentation_protocol(name, protocol.key, tuple(protocol.metrics))
    except ValueError as e:
        raise InputError(f"{where}: {e}") from None


def _order(protocol: Protocol) -> tuple[int, str]:
    return (protocol.order, protocol.name)


def score_by_set(protocol: Protocol, ctx: ProtocolContext) -> Block:
    """A protocol's `score_set(ctx, ids, mode, frame_set)` of every frame set and query mode, merged."""
    out = Block()
    for frame_set, ids in ctx.sets.items():
        for m in ctx.modes:
            out.merge(protocol.score_set(ctx, ids, m, frame_set))
    return out


_TABLE: PluginRegistry[Protocol] = PluginRegistry(kind=Protocol, noun="protocol", package=PROTOCOLS_PACKAGE,
                                                  suffix="_protocol", group=ENTRY_POINT_GROUP,
                                                  builtins=lambda module: [module.PROTOCOL], admit=_admit,
                                                  builtin_order=_order, log=log)


def builtin_protocol_modules() -> list[str]:
    """The `*_protocol` modules of gsbench.evaluation, found on its path."""
    return _TABLE.builtin_modules()


def register(protocol: Protocol, where: str = "register()") -> Protocol:
    """Add a protocol built at run time (the entry points' alternative; tests use it)."""
    return _TABLE.register(protocol, where)


def unregister(name: str) -> None:
    _TABLE.unregister(name)


def protocols() -> list[Protocol]:
    """Every registered protocol, in order."""
    return _TABLE.listing(key=_order)


def protocol_names() -> list[str]:
    return [p.name for p in protocols()]


def get_protocol(name: str) -> Protocol:
    _TABLE.load()
    if name not in _TABLE.items:
        raise InputError(f"unknown protocol {name!r}; registered: {', '.join(protocol_names())}")
    return _TABLE.items[name]


def fork_names() -> dict[str, str]:
    """{fork name: its protocol's name} of every registered fork."""
    return {f: p.name for p in protocols() for f in p.forks}


def parse_request(request: Optional[str]) -> dict[str, str]:
    """{protocol name: fork} of an explicit request ("3dovs-threshold,lerf"); {} for "auto" / None."""
    if request in (None, "", AUTO):
        return {}
    forks = fork_names()
    out: dict[str, str] = {}
    for item in (s.strip() for s in str(request).split(",")):
        if item in forks:
            name, fork = forks[item], item
        elif item in _TABLE.items:
            name, fork = item, _TABLE.items[item].default_fork
        else:
            known = ", ".join([AUTO] + [f"{p.name}{' (' + ', '.join(p.forks) + ')' if p.forks else ''}"
                                        for p in protocols()])
            raise InputError(f"unknown protocol or fork {item!r}; choose from: {known}")
        if name in out and out[name] != fork:
            raise InputError(f"--protocol {request}: two forks of protocol {name} ({out[name]}, {fork}); "
                             "score one fork per evaluation")
        out[name] = fork
    return out


def fork_of(results: dict, protocol: str) -> str:
    """The fork that produced a results.json's numbers of `protocol` (results written before forks
    were recorded read as the protocol's default fork)."""
    recorded = (results.get("forks") or {}).get(protocol)
    return recorded if recorded else get_protocol(protocol).default_fork


__all__ = ["Protocol", "ProtocolContext", "register", "unregister", "protocols", "protocol_names", "get_protocol",
           "fork_names", "parse_request", "fork_of", "score_by_set", "builtin_protocol_modules", "AUTO",
           "ENTRY_POINT_GROUP"]
