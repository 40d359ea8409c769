"""The table of methods gsbench knows: names, targets, labels, config sections (ground floor).

A method is registered once with a `MethodSpec`. The spec is data: its class, its resolver (what to
switch off when the scene cannot feed the method, with reasons) and its `uses` rule are named as
"module:attribute" strings, imported only by gsbench.methods.registry when a method is resolved or
run. So the config check (gsbench.config), the CLI choices and the report order read the table
without importing any method, and this module imports nothing of gsbench above the ground floor
(docs/architecture.md). The built-in methods are registered at the bottom, in report order.

    register(MethodSpec(name="mine", target="gsbench.methods.mine:Mine", label="Mine", section=None,
                        resolve="gsbench.methods.mine:resolve", uses="gsbench.methods.mine:uses"))
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
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
    per_frame_masks: bool = False        # semantic masks per view (not propagated across views)


_REGISTRY: dict[str, MethodSpec] = {}


class _Names(Sequence):
    """The registered names, in registration order, read live (a method registered later is in it)."""

    def __getitem__(self, i):  # type: ignore[override]
        return tuple(_REGISTRY)[i]

    def __len__(self) -> int:
        return len(_REGISTRY)

    def __iter__(self) -> Iterator[str]:
        return iter(tuple(_REGISTRY))

    def __contains__(self, name: object) -> bool:
        return name in _REGISTRY

    def __repr__(self) -> str:
        return repr(tuple(_REGISTRY))


METHODS: Sequence[str] = _Names()


def register(spec: MethodSpec) -> MethodSpec:
    """Add a method; a second registration of the same name is a programming error."""
    if not spec.name or not spec.name.replace("-", "").replace("_", "").isalnum():
        raise ValueError(f"method name {spec.name!r}: use letters, digits, '-' or '_'")
    if spec.name in _REGISTRY:
        raise ValueError(f"method {spec.name!r} is already registered (by {_REGISTRY[spec.name].target})")
    for field in ("target", "resolve", "uses"):
        value = getattr(spec, field)
        if not isinstance(value, str) or ":" not in value:
            raise ValueError(f"method {spec.name!r}: {field} must be 'module:attribute', got {value!r}")
    _REGISTRY[spec.name] = spec
    return spec


def unregister(name: str) -> None:
    """Remove a method (tests register throw-away methods)."""
    _REGISTRY.pop(name, None)


def get_spec(name: str) -> MethodSpec:
    if name not in _REGISTRY:
        raise InputError(f"unknown method {name!r}; choose one of {', '.join(_REGISTRY)}")
    return _REGISTRY[name]


def method_sort_key(name: Any) -> tuple[int, str]:
    """Report order: registration order, unknown names last (alphabetical)."""
    names = tuple(_REGISTRY)
    return (names.index(name) if name in names else len(names), str(name))


# registration order is the report order: the RGB baseline, the decoupled baseline, the joint
# identity-grouping baseline, the reference.
# Their resolvers live in gsbench/methods/registry.py.
_RULES = "gsbench.methods.registry"
register(MethodSpec(name="vanilla", target="gsbench.methods.vanilla:Vanilla", label="3DGS (vanilla)",
                    section=None, resolve=f"{_RULES}:resolve_vanilla", uses=f"{_RULES}:uses_vanilla"))
register(MethodSpec(name="twostage", target="gsbench.methods.twostage:TwoStage", label="Two-stage",
                    section="twostage", resolve=f"{_RULES}:resolve_twostage", uses=f"{_RULES}:uses_twostage",
                    per_frame_masks=True))
register(MethodSpec(name="grouping", target="gsbench.methods.grouping:GaussianGrouping",
                    label="Gaussian Grouping (style)", section="grouping", resolve=f"{_RULES}:resolve_grouping",
                    uses=f"{_RULES}:uses_grouping"))
register(MethodSpec(name="gaussiands", target="gsbench.methods.gaussiands:GaussianDS", label="GaussianDS",
                    section="gaussiands", resolve=f"{_RULES}:resolve_gaussiands", uses=f"{_RULES}:uses_gaussiands"))

__all__ = ["MethodSpec", "METHODS", "register", "unregister", "get_spec", "method_sort_key"]
