"""Floors, one direction: no gsbench module imports from a floor above its own (docs/architecture.md).

Every import statement of the package is read with `ast`, those inside functions included, plus
`importlib.import_module("gsbench...")` calls with a literal name. The top-level folders methods/,
datasets/, metrics/ and reports/ are read as gsbench.methods, gsbench.datasets, gsbench.metrics and
gsbench.reports (pyproject.toml [tool.setuptools] package-dir). Importing `a.b.c` also runs the
packages `a.b` and `a`, so those count as imported too. A function-level import of a gsbench module
must say why it is not at the top of its file, on its own line: `# lazy: <reason>`; there are at most
MAX_LAZY_IMPORTS of them. No two parts of gsbench (subpackages, top-level modules) import each other.
"""
from __future__ import annotations

import ast
import os
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

import pytest
from paths import REPO_ROOT

ROOT = REPO_ROOT
PACKAGE_DIRS = {"gsbench": "gsbench", "methods": "gsbench.methods", "datasets": "gsbench.datasets",
                "metrics": "gsbench.metrics", "reports": "gsbench.reports"}

# The one table of floors: a module's floor is that of its longest listed prefix. A new top-level
# module of gsbench/ has no prefix here and fails test_every_module_has_a_floor until it is placed.
FLOORS: dict[str, int] = {
    # 0 ground: types, files and settings every floor may use
    "gsbench": 0,                  # the package itself: process start-up settings
    "gsbench.errors": 0,
    "gsbench.camera": 0,           # Camera and the training-size rule
    "gsbench.gaussians": 0,
    "gsbench.store": 0,            # atomic file writes and reads
    "gsbench.results": 0,          # the results.json schema
    "gsbench.config": 0,
    "gsbench.config_keys": 0,
    "gsbench.yaml_reader": 0,      # the one YAML reader (budgets) and short texts for messages
    "gsbench.method_table": 0,     # method names and specs as data (no method imported)
    "gsbench.environment": 0,      # machine facts and peak memory
    "gsbench.numerics": 0,         # NUMERICS_VERSION: which generation of numbers a run belongs to
    "gsbench.runlock": 0,          # one writer per run folder
    "gsbench.outdir": 0,           # output folders: staged, swapped in, manifest of own files
    "gsbench.device": 0,           # the one device rule (train.device, a model prior's default)
    "gsbench.resize": 0,           # every resize: RGB as 3DGS, nearest as PIL, area
    "gsbench.rundir": 0,           # the run folder's file names, status reader beside its writer
    "gsbench.metric_table": 0,     # every metric name and how it is shown
    "gsbench.preview_files": 0,    # the previews folder of a run: manifest and arrays, writer and reader
    "gsbench.step_timers": 0,      # wall-time totals of a training step's parts (benchmarks/train_speed.py)
    "gsbench.plugin_registry": 0,  # the mechanics of the layouts' and the protocols' registries
    # 1: what a method is built from
    "gsbench.render": 1,
    "gsbench.priors": 1,
    "gsbench.metrics": 1,
    "gsbench.datasets": 1,
    # 2: the training engine, and the methods built on it (gsbench.train imports no method:
    # test_the_engine_imports_no_method)
    "gsbench.train": 2,
    "gsbench.methods": 2,
    # 3: what runs and scores methods
    "gsbench.evaluation": 3,
    "gsbench.runs": 3,
    "gsbench.grids": 3,
    "gsbench.collect": 3,          # results.json files -> one table
    "gsbench.stress": 3,           # numerical battery over render, losses and metrics
    # 4
    "gsbench.reports": 4,
    # 5 entry points: `gsbench report` calls reports, so the commands sit above them, with the CLI
    # that dispatches them
    "gsbench.commands": 5,
    "gsbench.cli": 5,
    "gsbench.commands.hostile": 5,          # the hostile-input battery runs the command line itself
}

# Upward imports still present, each with why and what would remove it. Empty: none remain. A new
# upward import fails; a listed one that no longer occurs fails too, so the list only shrinks.
ALLOWED_UPWARD: set[tuple[str, str]] = set()



@dataclass(frozen=True)
class Import:
    source: str          # importing module
    target: str          # imported gsbench module (longest existing module name)
    path: Path
    line: int
    in_function: bool
    reason: str          # text after "# lazy:" on the statement's lines ("" when none)


def modules(root: Path = ROOT) -> dict[str, Path]:
    """{dotted name: file} of every module of the package, with the package-dir mapping applied."""
    out: dict[str, Path] = {}
    for folder, package in PACKAGE_DIRS.items():
        base = root / folder
        for path in sorted(base.rglob("*.py")):
            parts = list(path.relative_to(base).with_suffix("").parts)
            if folder == "gsbench" and parts and parts[0] in PACKAGE_DIRS:
                continue
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([package, *parts])] = path
    return out


def _longest_module(name: str, known: dict[str, Path]) -> str:
    while name not in known and "." in name:
        name = name.rsplit(".", 1)[0]
    return name


def _lazy_reason(lines: list[str], node: ast.AST) -> str:
    for text in lines[node.lineno - 1: node.end_lineno]:
        if "# lazy:" in text:
            return text.split("# lazy:", 1)[1].strip()
    return ""


def _file_imports(source: str, path: Path, known: dict[str, Path]) -> list[Import]:
    text = path.read_text()
    lines = text.splitlines()
    found: list[Import] = []

    def add(name: str, node: ast.AST, in_function: bool) -> None:
        if name == "gsbench" or name.startswith("gsbench."):
            found.append(Import(source, _longest_module(name, known), path, node.lineno, in_function,
                                _lazy_reason(lines, node)))

    def relative_base(node: ast.ImportFrom) -> str:
        base = source.split(".") if path.name == "__init__.py" else source.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)]
        return ".".join(base + ([node.module] if node.module else []))

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                for alias in child.names:
                    add(alias.name, child, in_function)
            elif isinstance(child, ast.ImportFrom):
                module = relative_base(child) if child.level else (child.module or "")
                for alias in child.names:
                    sub = f"{module}.{alias.name}"
                    add(sub if sub in known else module, child, in_function)
            elif (isinstance(child, ast.Call) and isinstance(child.func, (ast.Attribute, ast.Name))
                  and getattr(child.func, "attr", getattr(child.func, "id", None)) == "import_module"
                  and child.args and isinstance(child.args[0], ast.Constant)
                  and isinstance(child.args[0].value, str)):
                add(child.args[0].value, child, True)
            visit(child, inner)

    visit(ast.parse(text, str(path)), False)
    return found


def imports(root: Path = ROOT) -> list[Import]:
    """Every import of a gsbench module by a gsbench module (a `from a import b` of submodule b
    counts as importing a.b)."""
    known = modules(root)
    return [imp for source, path in known.items() for imp in _file_imports(source, path, known)]


def floor(module: str) -> int:
    name = module
    while name not in FLOORS:
        if "." not in name:
            raise KeyError(f"{module} has no floor in tests/core/test_floors.py FLOORS")
        name = name.rsplit(".", 1)[0]
    return FLOORS[name]


def _imported(target: str) -> list[str]:
    """The module and the packages above it, which importing it runs too."""
    parts = target.split(".")
    return [".".join(parts[:i]) for i in range(len(parts), 0, -1)]


def upward(found: list[Import]) -> list[tuple[Import, str]]:
    return [(imp, t) for imp in found for t in _imported(imp.target) if floor(t) > floor(imp.source)]


def part_of(module: str) -> str:
    """The part of gsbench a module belongs to: its subpackage (gsbench.grids.store -> gsbench.grids)
    or, for a top-level module, the module itself (gsbench.config)."""
    return ".".join(module.split(".")[:2])


def package_edges(found: list[Import]) -> dict[tuple[str, str], Import]:
    """{(package, package it imports): the first import that makes the edge}, imports inside functions
    and the packages an import runs included, the root package `gsbench` left out (every import runs it)."""
    edges: dict[tuple[str, str], Import] = {}
    for imp in found:
        for t in _imported(imp.target):
            a, b = part_of(imp.source), part_of(t)
            if a != b and "gsbench" not in (a, b):
                edges.setdefault((a, b), imp)
    return edges


def package_cycles(edges: dict[tuple[str, str], Import]) -> list[list[str]]:
    """One cycle [a, b, ..., a] through each group of packages that import each other (a package
    reaches another and is reached back)."""
    succ: dict[str, set[str]] = {}
    for a, b in edges:
        succ.setdefault(a, set()).add(b)

    def path(start: str, goal: str) -> list[str] | None:
        """Shortest import path start -> ... -> goal (breadth first), None when goal is unreachable."""
        came: dict[str, str] = {start: start}
        todo = [start]
        while todo:
            nxt = []
            for node in todo:
                for b in sorted(succ.get(node, ())):
                    if b == goal:
                        out = [b, node]
                        while out[-1] != start:
                            out.append(came[out[-1]])
                        return out[::-1]
                    if b not in came:
                        came[b] = node
                        nxt.append(b)
            todo = nxt
        return None

    cycles, seen = [], set()
    for node in sorted(succ):
        if node in seen:
            continue
        cycle = path(node, node)
        if cycle:
            seen.update(cycle)
            cycles.append(cycle)
    return cycles


def lazy_statements(found: list[Import], root: Path = ROOT) -> list[str]:
    """Every function-level import statement of a gsbench module, once ("file:line"; a `from a import b,
    c` of two submodules is one statement)."""
    return sorted({f"{i.path.relative_to(root)}:{i.line}" for i in found if i.in_function})


# ---------------------------------------------------------------------------- the checker itself
def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, body in files.items():
        p = tmp_path / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(textwrap.dedent(body))
    for folder in PACKAGE_DIRS:
        (tmp_path / folder).mkdir(exist_ok=True)
    return tmp_path


def test_checker_sees_imports_in_functions_relative_and_import_module(tmp_path):
    root = _tree(tmp_path, {
        "gsbench/__init__.py": "",
        "gsbench/config.py": """
            import importlib
            def f():
                from gsbench.methods import base  # lazy: a reason
                return importlib.import_module("gsbench.reports.build")
            """,
        "gsbench/render/__init__.py": "from .kern import k\n",
        "gsbench/render/kern.py": "k = 1\n",
        "methods/__init__.py": "",
        "methods/base.py": "from . import other\nfrom gsbench.camera import Camera\n",
        "methods/other.py": "",
        "reports/__init__.py": "",
        "reports/build.py": "",
    })
    found = {(i.source, i.target, i.in_function, i.reason) for i in imports(root)}
    assert ("gsbench.config", "gsbench.methods.base", True, "a reason") in found
    assert ("gsbench.config", "gsbench.reports.build", True, "") in found
    assert ("gsbench.render", "gsbench.render.kern", False, "") in found
    assert ("gsbench.methods.base", "gsbench.methods.other", False, "") in found
    # gsbench.camera is not a file of this tree: the import names the longest module that exists
    assert ("gsbench.methods.base", "gsbench", False, "") in found
    bad = {(i.source, t) for i, t in upward(imports(root))}
    assert bad == {("gsbench.config", "gsbench.methods.base"), ("gsbench.config", "gsbench.methods"),
                   ("gsbench.config", "gsbench.reports.build"), ("gsbench.config", "gsbench.reports")}


def test_checker_finds_a_package_cycle(tmp_path):
    root = _tree(tmp_path, {
        "gsbench/__init__.py": "",
        "gsbench/config.py": "",
        "gsbench/evaluation/__init__.py": "from gsbench.evaluation.run import evaluate\n",
        "gsbench/evaluation/run.py": "def evaluate():\n    from gsbench.runs import load  # lazy: a cycle\n",
        "gsbench/runs/__init__.py": "from gsbench.runs.training import train\nload = 1\n",
        "gsbench/runs/training.py": "from gsbench.evaluation import evaluate\nfrom gsbench import config\ntrain = 1\n",
    })
    edges = package_edges(imports(root))
    assert set(edges) == {("gsbench.evaluation", "gsbench.runs"), ("gsbench.runs", "gsbench.evaluation"),
                          ("gsbench.runs", "gsbench.config")}
    assert package_cycles(edges) == [["gsbench.evaluation", "gsbench.runs", "gsbench.evaluation"]]
    del edges[("gsbench.evaluation", "gsbench.runs")]
    assert package_cycles(edges) == []
    assert lazy_statements(imports(root), root) == ["gsbench/evaluation/run.py:2"]


def test_checker_reads_the_package_dir_mapping_from_pyproject():
    text = (ROOT / "pyproject.toml").read_text()
    for folder, package in PACKAGE_DIRS.items():
        assert f'"{package}" = "{folder}"' in text


# ---------------------------------------------------------------------------- the tree
def test_every_module_has_a_floor():
    missing = []
    for name in modules():
        try:
            floor(name)
        except KeyError as e:
            missing.append(str(e))
    assert not missing, missing


def test_no_module_imports_from_a_floor_above():
    seen = {(imp.source, t) for imp, t in upward(imports())}
    new = sorted(f"{imp.path.relative_to(ROOT)}:{imp.line}: {imp.source} (floor {floor(imp.source)}) imports {t} "
                 f"(floor {floor(t)})" for imp, t in upward(imports()) if (imp.source, t) not in ALLOWED_UPWARD)
    assert not new, "upward imports:\n" + "\n".join(new)
    gone = sorted(ALLOWED_UPWARD - seen)
    assert not gone, f"no longer imported upward, remove from ALLOWED_UPWARD: {gone}"


def test_the_engine_imports_no_method():
    """gsbench.train sits beside gsbench.methods on floor 2 and below it in use: the methods build on the
    engine, never the other way (a method's own parts reach the engine as arguments: its loss, its
    strategy, its extra optimiser)."""
    bad = sorted(f"{i.path.relative_to(ROOT)}:{i.line}: {i.source} imports {t}" for i in imports()
                 for t in _imported(i.target)
                 if part_of(i.source) == "gsbench.train" and part_of(t) == "gsbench.methods")
    assert not bad, "the engine imports a method module:\n" + "\n".join(bad)


def test_every_function_level_import_says_why():
    bare = [i for i in imports() if i.in_function and not i.reason]
    new = sorted({f"{i.path.relative_to(ROOT)}:{i.line}: {i.source} imports {i.target} inside a function"
                  for i in bare})
    assert not new, "add '# lazy: <reason>' or move the import to the top:\n" + "\n".join(new)


# At most this many function-level imports of gsbench modules (statements). Most are the commands'
# heavy parts (reports, collect, stress) and optional backends; one whose module every command
# already loads, or that no cycle or floor keeps down, belongs at the top of its file.
MAX_LAZY_IMPORTS = 30


def test_function_level_imports_stay_few():
    lazy = lazy_statements(imports())
    assert len(lazy) <= MAX_LAZY_IMPORTS, (f"{len(lazy)} function-level imports of gsbench modules (at most "
                                           f"{MAX_LAZY_IMPORTS}); move one to the top of its file:\n"
                                           + "\n".join(lazy))


def test_no_two_packages_import_each_other():
    """No cycle between the parts of gsbench (subpackages and top-level modules), imports inside
    functions included: of two packages that need each other, the shared piece moves below both."""
    edges = package_edges(imports())
    found = []
    for cycle in package_cycles(edges):
        steps = [edges[(a, b)] for a, b in zip(cycle, cycle[1:])]
        found.append(" -> ".join(cycle) + "\n" + "\n".join(
            f"    {i.path.relative_to(ROOT)}:{i.line}: {i.source} imports {i.target}" for i in steps))
    assert not found, "package import cycles:\n" + "\n".join(found)


def test_the_ground_floor_loads_no_module_above_it(tmp_path):
    """At run time too: importing the ground floor leaves every higher floor unloaded. The child runs in
    an empty folder: from the checkout's parent, a clone named `gsbench` would be imported as a
    namespace package."""
    ground = sorted(m for m in modules() if floor(m) == 0)
    code = ("import sys\n" + "".join(f"import {m}\n" for m in ground)
            + "print('\\n'.join(sorted(m for m in sys.modules if m.startswith('gsbench'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path)
    loaded = [m for m in out.stdout.split() if m in modules()]
    assert set(ground) <= set(loaded)
    assert [m for m in loaded if floor(m) > 0] == []



# argv[1]: the third-party modules gsbench imports, comma-separated; argv[2:]: the gsbench modules.
# Third-party start-up is paid once, before the forks (it was ~75 % of this test's time); the parent
# still holds no gsbench module, so each child imports its module and the gsbench ones it needs from
# nothing. The children run a few at a time (one per core).
_IMPORT_EACH = """
import importlib, os, sys
for name in sys.argv[1].split(","):
    try:
        importlib.import_module(name)
    except ImportError:   # an optional dependency, or `from a import b` of a name b that is not a module
        pass
held = [m for m in sys.modules if m == "gsbench" or m.startswith("gsbench.")]
if held:
    sys.exit(f"the parent must hold no gsbench module, holds {held}")
failed, running = [], {}


def reap():
    pid, status = os.wait()
    name = running.pop(pid, None)
    if name is not None and status != 0:
        failed.append(name)


for name in sys.argv[2:]:
    while len(running) >= len(os.sched_getaffinity(0)):
        reap()
    pid = os.fork()
    if pid == 0:
        try:
            importlib.import_module(name)
        except BaseException as e:
            print(f"{name}: {type(e).__name__}: {e}", flush=True)
            os._exit(1)
        os._exit(0)
    running[pid] = name
while running:
    reap()
sys.exit(1 if failed else 0)
"""


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")
def test_every_module_imports_first_in_a_fresh_process(tmp_path):
    """Each module imported first, alone (a forked child of a process holding no gsbench module): an
    import cycle that the order of a test run hides fails here. Run from an empty folder (see above)."""
    names = sorted(modules())
    out = subprocess.run([sys.executable, "-c", _IMPORT_EACH, ",".join(third_party_imports()), *names],
                         capture_output=True, text=True, cwd=tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr


def third_party_imports(root: Path = ROOT) -> list[str]:
    """Every non-gsbench module that a gsbench module imports at load time (outside functions); for
    `from a import b`, a.b too (it may be a module). The forking parent imports them once beforehand."""
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                continue
            if isinstance(child, ast.Import):
                found.update(alias.name for alias in child.names)
            elif isinstance(child, ast.ImportFrom) and not child.level and child.module:
                found.update([child.module, *(f"{child.module}.{alias.name}" for alias in child.names)])
            visit(child)

    for path in modules(root).values():
        visit(ast.parse(path.read_text(), str(path)))
    return sorted(n for n in found if n.split(".")[0] != "gsbench")
