"""Config defaults live in gsbench/configs/default.yaml and the methods' specs and are read through
gsbench.config.setting, never restated at a call site: a `.get("<key>", <default.yaml's
value for that key>)` in the package is flagged. The listed sites take a section dict that callers
and tests may give partially; the list may only shrink."""
from __future__ import annotations

import ast
from pathlib import Path

from paths import REPO_ROOT

from gsbench.config import default_tree, flatten

FOLDERS = ("gsbench", "methods", "metrics", "datasets", "reports")
# (file, key) sites still restating a default, each reading a config *section* handed in as a dict
ALLOWED: set[tuple[str, str]] = {
    ("gsbench/priors/depth.py", "distortion"),
    ("gsbench/priors/depth.py", "severity"), ("gsbench/priors/segmenter.py", "severity"),
    ("gsbench/priors/features.py", "provider"), ("gsbench/priors/features.py", "noise"),
    ("gsbench/priors/features.py", "context"), ("gsbench/priors/features.py", "model"),
    ("gsbench/priors/pipeline.py", "provider"), ("gsbench/priors/pipeline.py", "new_objects"),
    ("gsbench/priors/pipeline.py", "propagator"), ("gsbench/priors/pipeline.py", "ordering"),
    ("gsbench/priors/pipeline.py", "per_track"), ("gsbench/train/semantic_targets.py", "epochs"),
    ("gsbench/train/semantic_targets.py", "lr"),
    ("gsbench/train/semantic_targets.py", "hidden"), ("gsbench/priors/masks.py", "generator"),
    # not config sections: a scene's gsbench_scene.json, a grid file's scene entry
    ("datasets/loader.py", "generator"), ("gsbench/grids/grid_file.py", "seed"),
}


def _defaults_by_leaf() -> dict[str, list]:
    out: dict[str, list] = {}
    for key, value in flatten(default_tree()).items():
        out.setdefault(key.rsplit(".", 1)[-1], []).append(value)
    return out


def _same(a, b) -> bool:
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return list(a) == list(b)
    return type(a) is type(b) and a == b or (isinstance(a, (int, float)) and isinstance(b, (int, float))
                                              and not isinstance(a, bool) and not isinstance(b, bool) and a == b)


def restated(root: Path = REPO_ROOT, folders: tuple[str, ...] = FOLDERS) -> set[tuple[str, str]]:
    leaves = _defaults_by_leaf()
    found = set()
    for folder in folders:
        for path in sorted((root / folder).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                        and node.func.attr == "get" and len(node.args) == 2):
                    continue
                key = node.args[0]
                if not (isinstance(key, ast.Constant) and isinstance(key.value, str) and key.value in leaves):
                    continue
                try:
                    default = ast.literal_eval(node.args[1])
                except ValueError:
                    continue
                if default is not None and any(_same(default, v) for v in leaves[key.value]):
                    found.add((str(path.relative_to(root)), key.value))
    return found


def test_no_call_site_restates_a_default_of_default_yaml():
    found = restated()
    new = sorted(found - ALLOWED)
    assert not new, "read these with gsbench.config.setting(config, 'a.b') instead:\n" + "\n".join(map(str, new))
    gone = sorted(ALLOWED - found)
    assert not gone, f"no longer restated, remove from ALLOWED: {gone}"




def test_the_detector_finds_a_planted_restated_default(tmp_path):
    """eval.fps_warmup's default is 3: `.get("fps_warmup", 3)` restates it, `.get("fps_warmup", 4)`
    and `.get("fps_warmup")` do not."""
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "a.py").write_text('def f(ev):\n    return ev.get("fps_warmup", 3)\n')
    (tmp_path / "pkg" / "b.py").write_text('def f(ev):\n    return ev.get("fps_warmup", 4), ev.get("fps_warmup")\n')
    assert restated(tmp_path, ("pkg",)) == {("pkg/a.py", "fps_warmup")}
