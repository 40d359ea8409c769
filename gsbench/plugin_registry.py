"""The mechanics a registry of plugins shares (ground floor): the layouts' and the protocols' registries.

A `PluginRegistry` holds the items registered under their `name`. On first use (`load`, guarded against
re-entry: a built-in module that asks the registry while it is being imported finds it as it stands) it
imports the built-in modules, those of one package whose names end in a suffix (found with pkgutil, so
there is no list to keep), then loads the entry points of one group: an entry point names an item, or a
function returning one. A plugin that cannot be loaded is one `InputError` naming the entry point and its
distribution. What each registry checks before an item is entered (its type, its name rules, a table of
its own to fill) is the `admit` function it passes in; the registry itself knows no item type.
"""
from __future__ import annotations

import importlib
import logging
import pkgutil
from importlib.metadata import entry_points
from typing import Any, Callable, Generic, Iterable, Optional, TypeVar

from gsbench.errors import InputError

T = TypeVar("T")


def entry_point_where(ep: Any, group: str) -> str:
    """How an error or a log line names an entry point: its name, its value, its distribution, its group."""
    dist = getattr(ep, "dist", None)
    return (f"entry point {ep.name!r} = {ep.value!r} of "
            f"{dist.name if dist is not None else 'an unnamed distribution'} (group {group})")


def _one(obj: Any) -> list:
    return [obj]


class PluginRegistry(Generic[T]):
    """Items of one kind by name: built-in modules of a package, then the entry points of a group.

    kind: the item type (an entry point naming a callable that is not one is called for the item);
    noun: what the log calls an item; package, suffix: where the built-in modules are and how their
    names end; group: the entry-point group; builtins(module) -> the items a built-in module holds;
    admit(item, where) checks an item before it is entered (InputError naming `where` otherwise);
    declared(obj) -> the items an entry point's object holds (default: the object itself);
    builtin_order: the key the built-ins are entered in (default: module order, each module's items
    entered as it is imported); log: the owner's logger."""

    def __init__(self, *, kind: type, noun: str, package: str, suffix: str, group: str,
                 builtins: Callable[[Any], Iterable[T]], admit: Callable[[Any, str], None],
                 declared: Callable[[Any], list] = _one, builtin_order: Optional[Callable[[T], Any]] = None,
                 log: Optional[logging.Logger] = None) -> None:
        self.kind, self.noun, self.package, self.suffix, self.group = kind, noun, package, suffix, group
        self._builtins, self._admit, self._declared, self._order = builtins, admit, declared, builtin_order
        self._log = log or logging.getLogger(__name__)
        self.items: dict[str, T] = {}
        self._loaded = False
        self._loading = False

    def builtin_modules(self) -> list[str]:
        """The modules of the package whose names end in the suffix, found on its path."""
        package = importlib.import_module(self.package)
        return sorted(f"{self.package}.{m.name}" for m in pkgutil.iter_modules(package.__path__)
                      if m.name.endswith(self.suffix) and not m.ispkg)

    def load(self) -> None:
        """Register the built-ins, then the entry points' (once; a broken plugin is one error)."""
        if self._loaded or self._loading:
            return
        self._loading = True
        try:
            found = ((item, m) for m in self.builtin_modules() for item in self._builtins(importlib.import_module(m)))
            if self._order is not None:
                order = self._order
                found = iter(sorted(found, key=lambda f: order(f[0])))
            for item, module in found:
                self.add(item, module)
            for ep in entry_points(group=self.group):
                where = entry_point_where(ep, self.group)
                try:
                    obj = ep.load()
                    obj = obj() if callable(obj) and not isinstance(obj, self.kind) else obj
                except Exception as e:  # a plugin that cannot be imported: say which and why
                    raise InputError(f"{where}: cannot be loaded: {type(e).__name__}: {e}") from e
                for item in self._declared(obj):
                    self.add(item, where)
            self._loaded = True
        finally:
            self._loading = False

    def add(self, item: Any, where: str) -> None:
        """Enter an item once `admit` has accepted it."""
        self._admit(item, where)
        self.items[item.name] = item
        self._log.debug("%s %s registered by %s", self.noun, item.name, where)

    def register(self, item: T, where: str = "register()") -> T:
        """Add an item built at run time (the entry points' alternative; tests use it)."""
        self.load()
        self.add(item, where)
        return item

    def unregister(self, name: str) -> None:
        self.items.pop(name, None)

    def listing(self, key: Callable[[T], Any]) -> list[T]:
        """Every registered item, sorted by `key`."""
        self.load()
        return sorted(self.items.values(), key=key)


__all__ = ["PluginRegistry", "entry_point_where"]
