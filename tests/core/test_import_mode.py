"""The suite sees the package as gsbench.* only: the repository's top-level folders (datasets/,
metrics/, methods/, reports/) must not import under their bare names, where `datasets` would
shadow Hugging Face's package of that name (pyproject.toml: --import-mode=importlib)."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from paths import REPO_ROOT


def test_repository_root_is_not_on_sys_path():
    entries = {Path(p or ".").resolve() for p in sys.path}
    assert REPO_ROOT.resolve() not in entries


def test_top_level_folders_do_not_import_by_bare_name():
    for name in ("datasets", "metrics", "methods", "reports"):
        spec = importlib.util.find_spec(name)
        origin = None if spec is None else (spec.origin or str(list(spec.submodule_search_locations or [])))
        assert spec is None or str(REPO_ROOT) not in str(origin), f"{name} imports from the repository: {origin}"


def test_the_mapped_packages_import_as_gsbench():
    import gsbench.datasets
    import gsbench.metrics
    assert Path(gsbench.datasets.__file__).resolve().parent == REPO_ROOT / "datasets"
    assert Path(gsbench.metrics.__file__).resolve().parent == REPO_ROOT / "metrics"
