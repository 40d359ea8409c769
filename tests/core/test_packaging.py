"""pyproject.toml lists every package folder, so a non-editable install (`pip install --target DIR .`,
as on the GPU machine or in benchmarks/versus.py) holds the whole of gsbench."""
import tomllib

from paths import REPO_ROOT


def test_every_package_folder_is_listed():
    tool = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(tool["packages"])
    found = set()
    for name, folder in tool["package-dir"].items():
        root = REPO_ROOT / folder
        for init in root.rglob("__init__.py"):
            if "__pycache__" in init.parts:
                continue
            rel = init.parent.relative_to(root).parts
            found.add(".".join((name, *rel)))
    assert found - listed == set(), f"package folders missing from pyproject.toml packages: {sorted(found - listed)}"
    assert listed - found == set(), f"listed packages without a folder: {sorted(listed - found)}"
