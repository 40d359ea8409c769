"""No function or method in the package sources is longer than 80 lines (issue 41): a long function is
split into named helpers so each piece can be read and tested on its own. Numba kernels are exempt
(a kernel split into calls can lose inlining and vectorisation, and they are checked bit for bit
elsewhere). Length is end_lineno - lineno + 1 of the `def`, decorators excluded."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOURCE_DIRS = ("gsbench", "methods", "datasets", "metrics", "reports")
MAX_LINES = 80
_NUMBA_NAMES = {"njit", "jit", "vectorize", "guvectorize", "stencil", "cfunc", "generated_jit"}


def _is_numba_decorator(node: ast.expr) -> bool:
    """`@njit`, `@njit(...)`, `@jit(...)`, `@numba.njit(...)`, `@numba.anything`."""
    if isinstance(node, ast.Call):
        node = node.func
    if isinstance(node, ast.Name):
        return node.id in _NUMBA_NAMES
    if isinstance(node, ast.Attribute):
        base = node.value
        while isinstance(base, ast.Attribute):
            base = base.value
        return (isinstance(base, ast.Name) and base.id == "numba") or node.attr in _NUMBA_NAMES
    return False


def long_functions(root: Path = ROOT, limit: int = MAX_LINES) -> list[tuple[str, int, str, int]]:
    """(file, line, qualified name, length) of every non-numba function longer than `limit` lines."""
    found = []
    for folder in SOURCE_DIRS:
        for path in sorted((root / folder).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
            found.extend(_walk(tree, path.relative_to(root).as_posix(), "", limit))
    return found


def _walk(node: ast.AST, rel: str, prefix: str, limit: int) -> list[tuple[str, int, str, int]]:
    found = []
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.ClassDef):
            found.extend(_walk(child, rel, f"{prefix}{child.name}.", limit))
        elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
            name = f"{prefix}{child.name}"
            length = child.end_lineno - child.lineno + 1
            if length > limit and not any(_is_numba_decorator(d) for d in child.decorator_list):
                found.append((rel, child.lineno, name, length))
            found.extend(_walk(child, rel, f"{name}.", limit))
        else:
            found.extend(_walk(child, rel, prefix, limit))
    return found


def test_no_function_over_80_lines():
    offenders = long_functions()
    report = "\n".join(f"{rel}:{line} {name} ({length} lines)" for rel, line, name, length in offenders)
    assert not offenders, f"functions over {MAX_LINES} lines (split them into named helpers):\n{report}"


if __name__ == "__main__":
    for rel, line, name, length in long_functions():
        print(f"{rel}:{line} {name} ({length} lines)")
