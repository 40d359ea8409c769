"""`scripts/warm_imports.py` (run by `make install`) imports every module of the package, those of the
folders pyproject.toml maps into gsbench included: the floors test's list of modules, read from files."""
import importlib.util
import sys

from paths import REPO_ROOT

sys.path.insert(0, str(REPO_ROOT / "tests" / "core"))
from test_floors import modules  # noqa: E402


def test_imports_every_module_of_the_package():
    spec = importlib.util.spec_from_file_location("warm_imports", REPO_ROOT / "scripts" / "warm_imports.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.import_all() == sorted(modules())
