"""Load a script of benchmarks/ as a module (the folder is not a package), for its smoke tests."""
import importlib.util
from types import ModuleType

from paths import REPO_ROOT


def load_benchmark(name: str) -> ModuleType:
    """benchmarks/<name>.py as a fresh module."""
    spec = importlib.util.spec_from_file_location(f"benchmark_{name}", REPO_ROOT / "benchmarks" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
