"""`gsbench data check`: a generated scene is clean; each broken copy gives one problem line naming
its file and exit status 1; several breaks are all listed."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from gsbench.cli import main
from gsbench.datasets.check import check_folder


def run_check(capsys, path, *extra) -> tuple[int, list[str]]:
    rc = main(["data", "check", str(path), *extra])
    return rc, capsys.readouterr().out.splitlines()


def problems(lines: list[str]) -> list[str]:
    return [ln.strip()[len("problem: "):] for ln in lines if ln.strip().startswith("problem: ")]


@pytest.fixture()
def copy(tiny_scene, tmp_path) -> Path:
    out = tmp_path / "scene"
    shutil.copytree(tiny_scene, out)
    return out


def label_dir(root: Path) -> Path:
    (d,) = [p for p in (root / "label").iterdir() if p.is_dir()]
    return d


def test_clean_generated_scene(tiny_scene, capsys):
    rc, lines = run_check(capsys, tiny_scene)
    text = "\n".join(lines)
    assert rc == 0 and lines[-1] == "problems  none"
    assert "layout    3dovs+lerf" in text and "views     8 images, 32x24" in text
    assert "points    " in text and "sparse points" in text and "poses     8 from" in text
    assert "classes   " in text and "queries   " in text
    # every labelled frame listed with its size: 8 views with 3D-OVS masks, 8 with LERF label files
    assert sum("class masks 32x24" in ln for ln in lines) == 8
    assert sum(".json 32x24," in ln for ln in lines) == 8


def _missing_class_mask(root):
    f = root / "segmentations" / "003" / "ball.png"
    f.unlink()
    return f, "class mask missing"


def _label_aspect(root):
    f = label_dir(root) / "frame_00005.json"
    d = json.loads(f.read_text())
    d["info"]["width"], d["info"]["height"] = 32, 32
    f.write_text(json.dumps(d))
    return f, "another aspect ratio"


def _frame_beyond_images(root):
    f = label_dir(root) / "frame_00009.json"     # 8 images: frame_00008 is the last
    shutil.copy(label_dir(root) / "frame_00008.json", f)
    return f, "outside the 8 images"


def _pose_count(root):
    f = root / "poses_bounds.npy"
    np.save(f, np.load(f)[:7])
    return f, "7 poses but 8 images"


def _mask_size(root):
    import cv2
    f = root / "segmentations" / "002" / "wall.png"
    cv2.imwrite(str(f), np.zeros((12, 16), np.uint8))
    return f, "mask is 16x12, image is 32x24"


def _mask_values(root):
    import cv2
    f = root / "segmentations" / "004" / "floor.png"
    m = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(f), (m > 0).astype(np.uint8))      # a 0/1 mask: the protocols read only 255 as foreground
    return f, "neither 0 nor 255"


def _label_name(root):
    f = label_dir(root) / "frame_00002.json"
    d = json.loads(f.read_text())
    d["info"]["name"] = "frame_00003.jpg"          # LangSplat would score this file against view 2, gsbench view 1
    f.write_text(json.dumps(d))
    return f, "info.name is 'frame_00003.jpg'"


@pytest.mark.parametrize("breaker", [_missing_class_mask, _label_aspect, _frame_beyond_images, _pose_count,
                                     _mask_size, _mask_values, _label_name])
def test_broken_copy_one_problem_line_naming_the_file(copy, capsys, breaker):
    f, what = breaker(copy)
    # poses_bounds.npy is read as the 3D-OVS protocol reads it (layout 3dovs); the rest as detected
    extra = ["--layout", "3dovs"] if breaker is _pose_count else []
    rc, lines = run_check(capsys, copy, *extra)
    found = problems(lines)
    assert rc == 1 and len(found) == 1, found
    assert found[0].startswith(f"{f}:") and what in found[0]


def test_every_problem_is_listed_not_only_the_first(copy):
    broken = [_missing_class_mask(copy)[0], _label_aspect(copy)[0], _frame_beyond_images(copy)[0]]
    f = copy / "segmentations" / "005" / "can.png"
    f.write_bytes(b"not a png")
    rep = check_folder(copy)
    assert not rep.ok and len(rep.problems) == 4
    for path in broken + [f]:
        assert sum(p.startswith(f"{path}:") for p in rep.problems) == 1


def test_not_a_scene(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    rc, lines = run_check(capsys, tmp_path / "empty")
    assert rc == 1 and len(problems(lines)) == 1 and "unknown scene layout" in problems(lines)[0]
