"""The one YAML reader of configs, presets, grid files and `--set` values, and short texts for messages.

It reads `1e-4` as a number (YAML 1.1 would read a string) and refuses a text over its size, node
(aliases expanded) or depth budget, naming where the text came from and never echoing it. Its own
module (ground floor) because every reader of user YAML needs it, not only the config.
"""
from __future__ import annotations

import re
import reprlib
from pathlib import Path
from typing import Any

import yaml

from gsbench.errors import InputError
from gsbench.store import read_text_bounded


class _Loader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """PyYAML's safe loader (YAML 1.1) reads `1e-4` as a string; this one reads it as a float, as YAML 1.2
    does. A quoted "1e-4" stays a string. It parses with libyaml where PyYAML has it (the same trees,
    about 10x faster: a grid resolves every cell's config from default.yaml), else in Python."""


_Loader.add_implicit_resolver("tag:yaml.org,2002:float",
                              re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
                              list("-+0123456789"))


# Budgets of every YAML text gsbench reads. The largest shipped file is 7 KB and 278 nodes. An alias
# repeats a node without repeating its text, so ten lines can stand for a billion nodes ("billion
# laughs"): the node budget counts every node as often as aliases repeat it, before anything is built.
MAX_YAML_BYTES = 1024 * 1024
MAX_YAML_NODES = 50_000
MAX_YAML_DEPTH = 64


def _check_nodes(root: yaml.Node, where: str) -> None:
    """Refuse a composed document over MAX_YAML_NODES (counting a node as often as aliases repeat it)
    or nested deeper than MAX_YAML_DEPTH, before anything is built. The walk stops at the first limit
    it meets, so an alias bomb costs at most MAX_YAML_NODES steps and an alias to itself (a node that
    contains itself) is refused as too deep; the depth limit also bounds the walk's recursion."""
    seen = 0

    def visit(node: yaml.Node, depth: int) -> None:      # a mapping or sequence node
        nonlocal seen
        if depth >= MAX_YAML_DEPTH:
            raise InputError(f"{where}: refused: YAML nested deeper than {MAX_YAML_DEPTH} levels")
        if type(node) is yaml.MappingNode:
            seen += 2 * len(node.value)
            inner = [n for pair in node.value for n in pair if type(n) is not yaml.ScalarNode]
        else:
            seen += len(node.value)
            inner = [n for n in node.value if type(n) is not yaml.ScalarNode]
        if seen > MAX_YAML_NODES:
            raise InputError(f"{where}: refused: YAML of more than {MAX_YAML_NODES} nodes once its aliases "
                             "are expanded (an alias bomb?)")
        for child in inner:
            visit(child, depth + 1)

    if type(root) is not yaml.ScalarNode:
        visit(root, 0)


def _yaml_problem(e: yaml.YAMLError) -> str:
    """A YAML error on one short line: the problem and where it is (libyaml's text spans lines)."""
    problem = getattr(e, "problem", None) or str(e)
    mark = getattr(e, "problem_mark", None)
    at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return short_text(" ".join(str(problem).split())) + at


def load_yaml(text: str, where: str = "YAML") -> Any:
    """The one YAML reader of configs, presets, grid files and `--set` values. A text over the budgets
    above, or one that is not YAML, is an InputError naming `where` (never echoing the text)."""
    if len(text) > MAX_YAML_BYTES:
        raise InputError(f"{where}: refused: {len(text)} characters of YAML, more than the "
                         f"{MAX_YAML_BYTES // 2**20} MiB gsbench reads")
    loader = _Loader(text)
    try:
        root = loader.get_single_node()
        if root is None:
            return None
        _check_nodes(root, where)
        return loader.construct_document(root)
    except yaml.YAMLError as e:
        if "maximum nesting depth" in str(e):     # libyaml's own limit (1000 levels)
            raise InputError(f"{where}: refused: YAML nested deeper than {MAX_YAML_DEPTH} levels") from None
        raise InputError(f"{where}: invalid YAML ({_yaml_problem(e)})") from None
    except RecursionError:                       # PyYAML's Python parser, where libyaml is missing
        raise InputError(f"{where}: refused: YAML nested deeper than {MAX_YAML_DEPTH} levels") from None
    finally:
        loader.dispose()


def load_yaml_file(path: str | Path) -> Any:
    """A YAML file through `load_yaml`; one over MAX_YAML_BYTES is refused before it is read."""
    path = Path(path)
    try:
        text = read_text_bounded(path, MAX_YAML_BYTES, "YAML")
    except FileNotFoundError as e:
        raise InputError(str(e)) from None
    return load_yaml(text, str(path))


_SHORT = reprlib.Repr()
_SHORT.maxlevel, _SHORT.maxlist, _SHORT.maxdict, _SHORT.maxstring, _SHORT.maxother = 3, 8, 6, 60, 60


def short_text(text: str, limit: int = 120) -> str:
    """`text` cut to `limit` characters, for messages."""
    return text if len(text) <= limit else text[:limit - 3] + "..."


def short_repr(value: Any, limit: int = 120) -> str:
    """repr() for messages: a long list, mapping or string is cut (an error line never echoes a file)."""
    return short_text(_SHORT.repr(value), limit)


__all__ = ["load_yaml", "load_yaml_file", "short_text", "short_repr", "MAX_YAML_BYTES", "MAX_YAML_NODES",
           "MAX_YAML_DEPTH"]
