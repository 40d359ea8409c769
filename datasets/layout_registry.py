"""The registry of scene layouts: a layout is a reader plus its detection (docs/datasets.md "Adding a layout").

A layout file is a module of gsbench.datasets named `<anything>_layout` that holds `LAYOUT` (one `Layout`)
or `LAYOUTS` (several). The registry finds those modules on first use (no list of built-ins to keep; the
built-ins are `builtin_layout.py`), then the entry points of the `gsbench.layouts` group, so an installed
package adds a layout the same way:

    [project.entry-points."gsbench.layouts"]
    mine = "my_package.mine_layout:LAYOUT"

`register(layout)` is the hook for code that builds a layout at run time (tests). Detection (`detect`)
asks each layout with a `detect` rule, in `priority` order (smaller first), and takes the first that
answers yes.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional

from gsbench.errors import InputError
from gsbench.plugin_registry import PluginRegistry

log = logging.getLogger(__name__)

LAYOUTS_PACKAGE = "gsbench.datasets"
ENTRY_POINT_GROUP = "gsbench.layouts"
AUTO = "auto"


@dataclass(frozen=True)
class Layout:
    """One scene layout. A plugin needs `name`, `detect` and `read`; the built-ins use the other fields."""

    name: str                                          # the --layout value, recorded as Scene.layout
    detect: Optional[Callable[[Path], bool]] = None    # folder -> whether it is in this layout (None: never
    #                                                    detected, only read when asked for by name)
    read: Optional[Callable[[Path], Any]] = None       # folder -> Scene (everything it holds); default:
    #                                                    `cameras`, then each of `labels`
    priority: int = 100                                # detection order: smaller first (built-ins 10 to 70)
    aliases: tuple[str, ...] = ()                      # other names it answers to (`both` = `3dovs+lerf`)
    cameras: Optional[Callable[[Path], Any]] = None    # folder -> Scene of cameras and images only
    labels: tuple[Callable[[Any, Path], None], ...] = ()    # (scene, folder) -> None: attach a label part
    label_checks: tuple[Callable[..., None], ...] = ()      # (folder, names, sizes, report): `gsbench data check`
    extras: bool = True                                # a gsbench synthetic scene's GT (gsbench_scene.json) and
    #                                                    the shared-centre extent rule apply after reading
    check: Optional[Callable[[Path, Any], None]] = None     # (folder, report): a data check of its own
    described: str = ""                                # what detection looks for (for the error message)

    def load(self, root: Path):
        """The Scene of a folder in this layout (before the synthetic GT and the extent rule)."""
        if self.read is not None:
            return self.read(root)
        if self.cameras is None:
            raise InputError(f"layout {self.name}: has neither a reader nor a camera reader")
        scene = self.cameras(root)
        for attach in self.labels:
            attach(scene, root)
        return scene


def _declared(obj: Any) -> list:
    return list(obj) if isinstance(obj, (list, tuple)) else [obj]


def _builtins(module: Any) -> list:
    """The layouts a built-in `*_layout` module holds (`LAYOUTS`, or one `LAYOUT`)."""
    return _declared(getattr(module, "LAYOUTS", None) or getattr(module, "LAYOUT", None) or [])


def _admit(layout: Any, where: str) -> None:
    if not isinstance(layout, Layout):
        raise InputError(f"{where}: names {type(layout).__name__}, not a gsbench Layout")
    if not layout.name or layout.name == AUTO:
        raise InputError(f"{where}: layout name {layout.name!r} is empty or reserved")
    if layout.read is None and layout.cameras is None:
        raise InputError(f"{where}: layout {layout.name!r} has no reader (read= or cameras=)")
    taken = {n: lay.name for lay in _TABLE.items.values() for n in (lay.name, *lay.aliases)}
    for n in (layout.name, *layout.aliases):
        if n in taken:
            raise InputError(f"{where}: layout name {n!r} is already taken by layout {taken[n]!r}")


_TABLE: PluginRegistry[Layout] = PluginRegistry(kind=Layout, noun="layout", package=LAYOUTS_PACKAGE,
                                                suffix="_layout", group=ENTRY_POINT_GROUP, builtins=_builtins,
                                                admit=_admit, declared=_declared, log=log)


def builtin_layout_modules() -> list[str]:
    """The `*_layout` modules of gsbench.datasets, found on its path."""
    return _TABLE.builtin_modules()


def register(layout: Layout, where: str = "register()") -> Layout:
    """Add a layout built at run time (the entry points' alternative; tests use it)."""
    return _TABLE.register(layout, where)


def unregister(name: str) -> None:
    _TABLE.unregister(name)


def layouts() -> list[Layout]:
    """Every registered layout, in detection order."""
    return _TABLE.listing(key=lambda lay: (lay.priority, lay.name))


def layout_names() -> tuple[str, ...]:
    """"auto", then every layout's name and aliases."""
    return (AUTO, *[n for lay in layouts() for n in (lay.name, *lay.aliases)])


def get_layout(name: str) -> Layout:
    """The layout registered under a name or an alias (InputError naming the choices otherwise)."""
    for lay in layouts():
        if name == lay.name or name in lay.aliases:
            return lay
    raise InputError(f"unknown layout {name!r}; choose one of {', '.join(layout_names())}")


def detect_layout(root: Path) -> str:
    """The name of the first layout, in priority order, whose detection recognises the folder."""
    root = Path(root)
    for lay in layouts():
        if lay.detect is not None and lay.detect(root):
            return lay.name
    looked = ", ".join(lay.described for lay in layouts() if lay.described)
    raise InputError(f"{root}: unknown scene layout (looked for {looked})")


__all__ = ["Layout", "register", "unregister", "layouts", "layout_names", "get_layout", "detect_layout",
           "builtin_layout_modules", "AUTO", "ENTRY_POINT_GROUP"]
