"""The table of methods gsbench knows: names, targets, labels, config sections (ground floor).

A method is one file plus a spec beside it (docs/methods.md). The spec module holds a `MethodSpec`
named `SPEC`: data that names the method's class, its resolver (what to switch off when the scene
cannot feed the method, with reasons), its `uses` rule and its budget rule as "module:function"
strings, imported only when a method is resolved or run. The spec also owns the method's config
section: its defaults and the ranges or choices of its keys, and names the shared sections the method
reads (SHARED_SECTIONS: `semantic`, the latents several methods learn). This table discovers the spec
modules on first use: every `*_spec` module and every subpackage's `spec` module of gsbench.methods
(the built-ins: adding one is two files there, no list to edit), then every entry point of the
`gsbench.methods` group (an installed plugin package; the entry point names a MethodSpec, or a
function returning one). Report order is the specs' `order`, then their names. So the config check,
the CLI choices and the report order read the table without importing any method, and this module
imports nothing of gsbench above the ground floor (the spec modules are imported by name).

    [project.entry-points."gsbench.methods"]
    mine = "my_package.mine_spec:SPEC"
"""
from __future__ import annotations

import copy
import importlib
import logging
import pkgutil
from collections.abc import Sequence
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
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
    defaults: Optional[dict] = None      # defaults of the method's own `section` (default.yaml has none);
    #                                      checked like default.yaml's keys
    rules: Optional[dict] = None         # {"<section>.<key>": gsbench.config_keys.Rule}: ranges and choices
    #                                      of the own section's keys, beyond the type their default has
    shared: tuple[str, ...] = ()         # the SHARED_SECTIONS the method reads (the others leave its run id)
    order: int = 100                     # report order (smaller first; ties by name)
    moved: Optional[dict] = None         # {old dotted key: today's}: keys the method once kept elsewhere; configs
    #                                      of older runs are read in today's layout (gsbench.config.upgrade_config)


log = logging.getLogger(__name__)

METHODS_PACKAGE = "gsbench.methods"   # where the built-in methods and their specs live (methods/)
ENTRY_POINT_GROUP = "gsbench.methods"
# config sections of default.yaml that several methods read; a method names those it uses (MethodSpec.shared)
SHARED_SECTIONS = ("semantic",)

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
        specs = [(importlib.import_module(m).SPEC, m) for m in builtin_spec_modules()]
        for spec, module in sorted(specs, key=lambda s: (s[0].order, s[0].name)):
            _add(spec, module)
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


def builtin_spec_modules() -> list[str]:
    """The spec modules of gsbench.methods, found on its path: `<name>_spec` modules and the `spec` module
    of each subpackage (importing the package imports no method)."""
    package = importlib.import_module(METHODS_PACKAGE)
    found = []
    for info in pkgutil.iter_modules(package.__path__):
        if info.name.endswith("_spec") and not info.ispkg:
            found.append(f"{METHODS_PACKAGE}.{info.name}")
        elif info.ispkg and (Path(getattr(info.module_finder, "path", "")) / info.name / "spec.py").is_file():
            found.append(f"{METHODS_PACKAGE}.{info.name}.spec")
    return sorted(found)


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
    if spec.section in SHARED_SECTIONS:
        raise ValueError(f"method {spec.name!r}: section {spec.section!r} is shared by several methods; name it "
                         "in `shared` and give the method a section of its own")
    foreign = [k for k in (spec.rules or {}) if spec.section is None or not k.startswith(spec.section + ".")]
    if foreign:
        raise ValueError(f"method {spec.name!r}: rules may only name keys of its own section, not {foreign[0]!r}")
    unknown = [s for s in spec.shared if s not in SHARED_SECTIONS]
    if unknown:
        raise ValueError(f"method {spec.name!r}: shared section {unknown[0]!r} is not one of "
                         f"{', '.join(SHARED_SECTIONS)}")


def section_defaults() -> dict[str, dict]:
    """{section: defaults} of the registered methods that bring their own config section."""
    _load()
    return {s.section: copy.deepcopy(s.defaults) for s in _REGISTRY.values()
            if s.section is not None and s.defaults is not None}


def moved_keys() -> dict[str, str]:
    """{old dotted key: today's} of every registered method (MethodSpec.moved)."""
    _load()
    return {old: new for s in _REGISTRY.values() for old, new in (s.moved or {}).items()}


def method_rules() -> dict:
    """{dotted key: Rule} of every registered method's own section."""
    _load()
    return {k: r for s in _REGISTRY.values() for k, r in (s.rules or {}).items()}


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


__all__ = ["MethodSpec", "METHODS", "METHODS_PACKAGE", "SHARED_SECTIONS", "ENTRY_POINT_GROUP", "register",
           "unregister", "get_spec", "method_sort_key", "section_defaults", "method_rules", "moved_keys",
           "builtin_spec_modules"]
