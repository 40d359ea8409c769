"""The table of methods gsbench knows: names, targets, labels, config sections (ground floor).

A method is one file plus a spec beside it (docs/methods.md). The spec module holds a `MethodSpec`
named `SPEC`: data that names the method's class, its resolver (what to switch off when the scene
cannot feed the method, with reasons), its `uses` rule and its budget rule as "module:function"
strings, imported only when a method is resolved or run. This table loads the spec modules by name
on first use: the built-ins of BUILTIN_SPECS in report order, then every entry point of the
`gsbench.methods` group (an installed plugin package; the entry point names a MethodSpec, or a
function returning one). So the config check, the CLI choices and the report order read the table
without importing any method, and this module imports nothing of gsbench above the ground floor.

    [project.entry-points."gsbench.methods"]
    mine = "my_package.mine_spec:SPEC"
"""
from __future__ import annotations

import copy
import importlib
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any, Iterator, Optional

from gsbench.errors import InputError


@dataclass(frozen=True)
class MethodSpec:
    """What gsbench knows about a method without importing it."""

    name: str
    target: str                          # "module:Class" implementing gsbench.methods.base.Method
    label: str                           # name in tables and plots
    section: Optional[str]               # the method's own top-level config section (None: shared keys only)
    resolve: str                         # "module:function" (cfg, scene, drop) editing the config in place;
    #                                      drop(part, reason) records why
    uses: str                            # "module:function" resolved config -> {"depth_prior": bool, "semantics": bool}
    budget: str                          # "module:function" resolved config -> {"rgb_steps", "semantic_steps",
    #                                      "schedule": "joint" | "after rgb" | "none"} (semantic steps' place)
    per_frame_masks: bool = False        # semantic masks per view (not propagated across views)
    defaults: Optional[dict] = None      # defaults of the method's own `section` when default.yaml has none
    #                                      (a plugin's section); checked like default.yaml's keys


log = logging.getLogger(__name__)

# the built-in methods' spec modules, in report order: the RGB baseline, the decoupled baseline, the
# joint identity-grouping baseline, the reference
BUILTIN_SPECS = ("gsbench.methods.vanilla_spec", "gsbench.methods.twostage_spec", "gsbench.methods.grouping_spec",
                 "gsbench.methods.gaussiands.spec")
ENTRY_POINT_GROUP = "gsbench.methods"

_REGISTRY: dict[str, MethodSpec] = {}
_LOADED = False
_LOADING = False


def _load() -> None:
    """Register the built-in specs, then the plugins' (once; a broken plugin is one clear error)."""
    global _LOADED, _LOADING
    if _LOADED or _LOADING:
        return
    _LOADING = True
    try:
        for module in BUILTIN_SPECS:
            _add(importlib.import_module(module).SPEC, module)
        for ep in entry_points(group=ENTRY_POINT_GROUP):
            where = f"entry point {ep.name!r} = {ep.value!r} of {_dist_name(ep)} (group {ENTRY_POINT_GROUP})"
            try:
                obj = ep.load()
                spec = obj() if callable(obj) and not isinstance(obj, MethodSpec) else obj
            except Exception as e:  # a plugin that cannot be imported: say which and why
                raise InputError(f"{where}: cannot be loaded: {type(e).__name__}: {e}") from e
            if not isinstance(spec, MethodSpec):
                raise InputError(f"{where}: names {type(spec).__name__}, not a gsbench MethodSpec")
            _add(spec, where)
            log.debug("method %s registered by %s", spec.name, where)
        _LOADED = True
    finally:
        _LOADING = False


def _dist_name(ep) -> str:
    dist = getattr(ep, "dist", None)
    return f"distribution {dist.name}" if dist is not None else "an unnamed distribution"


def _add(spec: MethodSpec, where: str) -> None:
    try:
        _check(spec)
    except ValueError as e:
        raise InputError(f"{where}: {e}") from None
    if spec.name in _REGISTRY:
        raise InputError(f"{where}: method {spec.name!r} is already registered (by {_REGISTRY[spec.name].target})")
    _REGISTRY[spec.name] = spec


def _check(spec: MethodSpec) -> None:
    if not spec.name or not spec.name.replace("-", "").replace("_", "").isalnum():
        raise ValueError(f"method name {spec.name!r}: use letters, digits, '-' or '_'")
    for field in ("target", "resolve", "uses", "budget"):
        value = getattr(spec, field)
        if not isinstance(value, str) or ":" not in value:
            raise ValueError(f"method {spec.name!r}: {field} must be 'module:attribute', got {value!r}")
    if spec.defaults is not None and (spec.section is None or not isinstance(spec.defaults, dict)):
        raise ValueError(f"method {spec.name!r}: `defaults` must be a dict of its own config section")


def section_defaults() -> dict[str, dict]:
    """{section: defaults} of the registered methods that bring their own config section."""
    _load()
    return {s.section: copy.deepcopy(s.defaults) for s in _REGISTRY.values()
            if s.section is not None and s.defaults is not None}


class _Names(Sequence):
    """The registered names, in registration order, read live (a method registered later is in it)."""

    def __getitem__(self, i):  # type: ignore[override]
        _load()
        return tuple(_REGISTRY)[i]

    def __len__(self) -> int:
        _load()
        return len(_REGISTRY)

    def __iter__(self) -> Iterator[str]:
        _load()
        return iter(tuple(_REGISTRY))

    def __contains__(self, name: object) -> bool:
        _load()
        return name in _REGISTRY

    def __repr__(self) -> str:
        _load()
        return repr(tuple(_REGISTRY))


METHODS: Sequence[str] = _Names()


def register(spec: MethodSpec) -> MethodSpec:
    """Add a method by hand (tests; a package adds one through the entry-point group instead); a
    second registration of the same name is a programming error."""
    _load()
    _check(spec)
    if spec.name in _REGISTRY:
        raise ValueError(f"method {spec.name!r} is already registered (by {_REGISTRY[spec.name].target})")
    _REGISTRY[spec.name] = spec
    return spec


def unregister(name: str) -> None:
    """Remove a method (tests register throw-away methods)."""
    _REGISTRY.pop(name, None)


def get_spec(name: str) -> MethodSpec:
    _load()
    if name not in _REGISTRY:
        raise InputError(f"unknown method {name!r}; choose one of {', '.join(_REGISTRY)}")
    return _REGISTRY[name]


def method_sort_key(name: Any) -> tuple[int, str]:
    """Report order: registration order, unknown names last (alphabetical)."""
    _load()
    names = tuple(_REGISTRY)
    return (names.index(name) if name in names else len(names), str(name))


__all__ = ["MethodSpec", "METHODS", "BUILTIN_SPECS", "ENTRY_POINT_GROUP", "register", "unregister", "get_spec",
           "method_sort_key", "section_defaults"]
