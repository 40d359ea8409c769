"""Scene folders checked before use: cameras, poses, labels, polygons, paths and image sizes.

Every corruption of gsbench/commands/hostile/data.py is answered twice: `gsbench data check` lists it as a
problem (exit 1) and `gsbench train` stops with one line (exit 1). Hand-computed cases pin the
camera check, the fill work of a polygon and the pixel budget.
"""
from __future__ import annotations

import json
import shutil
import struct
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from gsbench.camera import intrinsics_problems, pose_problems, quaternion_matrix
from gsbench.cli import main
from gsbench.commands.hostile import run_hostile
from gsbench.commands.hostile.data import CASES, CORRUPTIONS, LABEL, TRAIN_ARGS, VIEW, nerf_scene, png_header
from gsbench.datasets import load_scene
from gsbench.datasets.imageio import image_size
from gsbench.datasets.label_limits import MAX_FILL_WORK, fill_work, label_problems, max_points
from gsbench.datasets.ovs import LabelObject, polygons_to_mask
from gsbench.errors import InputError


@pytest.fixture()
def copy(tiny_scene, tmp_path) -> Path:
    out = tmp_path / "scene"
    shutil.copytree(tiny_scene, out)
    return out


def check_problems(capsys, path) -> tuple[int, list[str]]:
    rc = main(["data", "check", str(path)])
    lines = capsys.readouterr().out.splitlines()
    return rc, [ln.strip()[len("problem: "):] for ln in lines if ln.strip().startswith("problem: ")]


def train_error(capsys, scene: Path, out: Path) -> tuple[int, str]:
    """Exit code and stderr of a train on `scene`, asserting it ends in one error line."""
    rc = main(["train", "--scene", str(scene), "--out", str(out), *TRAIN_ARGS])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err and "Warning" not in err, err
    assert lines and lines[-1].startswith("gsbench train: error: ") and len(lines[-1]) < 400, err
    return rc, lines[-1]


# ------------------------------------------------------------------------------------ every corruption
@pytest.mark.parametrize("corruption", CORRUPTIONS, ids=[c.name for c in CORRUPTIONS])
def test_data_check_lists_the_problem(copy, capsys, corruption):
    corruption.corrupt(copy)
    rc, found = check_problems(capsys, copy)
    assert rc == 1
    hits = [p for p in found if all(e in p for e in corruption.expect)]
    assert hits, found
    assert all(p.startswith(str(copy)) for p in hits)     # the line names the file in the scene


@pytest.mark.parametrize("corruption", CORRUPTIONS, ids=[c.name for c in CORRUPTIONS])
def test_train_refuses_in_one_line(copy, tmp_path, capsys, corruption):
    corruption.corrupt(copy)
    rc, line = train_error(capsys, copy, tmp_path / "run")
    assert rc == 1
    missing = [e for e in corruption.expect if e not in line]
    assert not missing, line
    assert not (tmp_path / "run" / "model").exists()


def test_data_check_lists_every_bad_view(copy, capsys):
    arr = np.load(copy / "poses_bounds.npy")
    arr[[1, 4], 0:3] = 0.0                    # first row of the rotation: rank 2 in two views
    np.save(copy / "poses_bounds.npy", arr)
    shutil.rmtree(copy / "sparse")
    rc, found = check_problems(capsys, copy)
    assert rc == 1
    bad = [p for p in found if "not a proper rotation" in p]
    assert len(bad) == 2
    assert "view frame_00002.png" in bad[0] and "view frame_00005.png" in bad[1]


def test_data_check_lists_every_broken_polygon_of_a_label_file(copy, capsys):
    f = copy / LABEL
    d = json.loads(f.read_text())
    d["objects"][0]["segmentation"] = [[0, 0], [200, 0], [0, 5]]           # x 200 beyond 2 x 32
    d["objects"][1]["segmentation"] = [[0, 0], [5, 0], [0, -100]]          # y -100 beyond -24
    f.write_text(json.dumps(d))
    rc, found = check_problems(capsys, copy)
    assert rc == 1 and len(found) == 2
    assert "object 0" in found[0] and "(200, 0)" in found[0]
    assert "object 1" in found[1] and "(0, -100)" in found[1]


# ------------------------------------------------------------------------------------ cameras by hand
def _rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _pose(R: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = R
    m[:3, 3] = [0.5, -1.0, 3.0]
    return m


def test_camera_check_by_hand():
    K = np.array([[30.0, 0, 16], [0, 30.0, 12], [0, 0, 1]])
    assert intrinsics_problems(K, 32, 24) == []
    assert pose_problems(_pose(_rot_z(0.7))) == []
    assert intrinsics_problems(np.diag([-5.0, 30.0, 1.0]) + [[0, 0, 16], [0, 0, 12], [0, 0, 0]], 32, 24) == [
        "focal length fx=-5 is not positive"]
    K_out = K.copy()
    K_out[1, 2] = 24.5
    assert intrinsics_problems(K_out, 32, 24) == ["principal point (16, 24.5) lies outside the 32x24 image"]
    K_nan = K.copy()
    K_nan[0, 0] = np.inf
    assert intrinsics_problems(K_nan, 32, 24) == ["intrinsics hold NaN or inf"]
    # 1.01 x a rotation: R R^T is off by 0.0201, det 1.0303
    (p,) = pose_problems(_pose(1.01 * _rot_z(0.3)))
    assert "det 1.03" in p and "up to 0.0201" in p
    # a rotation about z with its last axis flipped: a mirror, det -1
    (p,) = pose_problems(_pose(_rot_z(0.3) @ np.diag([1.0, 1.0, -1.0])))
    assert "det -1" in p
    bottom = _pose(np.eye(3))
    bottom[3, 2] = 1.0
    (p,) = pose_problems(bottom)
    assert "last row" in p


def test_quaternion_matrix_keeps_the_norm():
    # the unit quaternion (cos 0.3, 0, 0, sin 0.3) is a rotation by 0.6 about z
    q = np.array([np.cos(0.3), 0.0, 0.0, np.sin(0.3)])
    assert np.allclose(quaternion_matrix(q), _rot_z(0.6))
    assert np.allclose(quaternion_matrix(2 * q), 4 * _rot_z(0.6))
    assert not quaternion_matrix(np.zeros(4)).any()


# ------------------------------------------------------------------------------------ polygons
def test_fill_work_by_hand():
    # a 10 x 10 square: rows 0 and 10 are crossed by 3 edges (a horizontal side and the two
    # vertical ones), rows 1..9 by 2: 2 * 9 + 9 * 4 = 54
    assert fill_work(np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)) == 54
    # fractional coordinates are truncated as cv2.fillPoly does: the same square
    assert fill_work(np.array([[0.9, 0.2], [10.5, 0.9], [10.1, 10.7], [0.3, 10.2]])) == 54


def test_polygon_limits_follow_the_grid():
    assert max_points(32, 24) == 224 and max_points(985, 725) == 6840
    ok = LabelObject("a", [np.array([[-32.0, -24.0], [64.0, -24.0], [64.0, 48.0]])])
    assert label_problems(Path("f.json"), [ok], 32, 24) == []
    over = LabelObject("a", [np.array([[-32.1, 0.0], [5.0, 5.0], [0.0, 5.0]])])
    (p,) = label_problems(Path("f.json"), [over], 32, 24)
    assert "(-32.1, 0)" in p


def test_accepted_scribble_fills_fast():
    """The most crossing polygon the fill-work limit accepts on the real LERF label size fills in well
    under a second (a 20,000-point scribble took 10 s before the limit)."""
    rng = np.random.default_rng(0)
    w, h = 985, 725
    n = 6000
    while True:     # random points in a 20-row band: the slowest kind measured per unit of work
        pts = np.c_[rng.uniform(-w, 2 * w, n), rng.uniform(300, 320, n)]
        if fill_work(pts) <= MAX_FILL_WORK:
            break
        n -= 250
    assert label_problems(Path("f.json"), [LabelObject("a", [pts])], w, h) == []
    t0 = time.perf_counter()
    polygons_to_mask([pts], h, w)
    assert time.perf_counter() - t0 < 2.0


# ------------------------------------------------------------------------------------ paths and layouts
def test_outside_path_allowed_by_the_environment(tiny_scene, copy, tmp_path, monkeypatch):
    outside = tmp_path / "elsewhere" / VIEW
    outside.parent.mkdir()
    shutil.copy(copy / "images" / VIEW, outside)
    nerf_scene(copy, lambda frame: frame.update(file_path=str(outside)))
    (copy / "gsbench_scene.json").unlink()      # its image list is in name order; this one sorts first
    with pytest.raises(InputError, match="lies outside the scene folder"):
        load_scene(copy)
    monkeypatch.setenv("GSBENCH_ALLOW_OUTSIDE_PATHS", "1")
    scene = load_scene(copy)
    i = scene.image_paths.index(str(outside))
    assert np.array_equal(scene.image(i), load_scene(tiny_scene).image(2))


def test_climbing_back_inside_is_inside(copy):
    nerf_scene(copy, lambda frame: frame.update(file_path=f"images/../images/{VIEW}"))
    (copy / "gsbench_scene.json").unlink()      # its image list is in name order; this one sorts first
    assert str(copy / "images" / ".." / "images" / VIEW) in load_scene(copy).image_paths


def test_nerf_data_check_names_the_poses_file(copy, capsys):
    nerf_scene(copy)
    rc, found = check_problems(capsys, copy)
    assert rc == 0 and found == []
    main(["data", "check", str(copy)])
    out = capsys.readouterr().out
    assert f"poses     8 from {copy / 'transforms.json'}" in out


# ------------------------------------------------------------------------------------ image sizes
def _bmp_header(path: Path, width: int, height: int) -> None:
    """A 24-bit BMP that is only its 54-byte header (PIL reads the size from it)."""
    info = struct.pack("<IiiHHIIiiII", 40, width, height, 1, 24, 0, 0, 2835, 2835, 0, 0)
    path.write_bytes(b"BM" + struct.pack("<IHHI", 54, 0, 0, 54) + info)


def test_pixel_budget_without_warning_noise(tmp_path):
    png_header(tmp_path / "a.png", 10000, 9500)        # 95 MP: under the budget
    _bmp_header(tmp_path / "b.png", 10000, 9500)       # PIL warns of a bomb above 89.5 MP
    _bmp_header(tmp_path / "c.png", 12000, 9000)       # 108 MP: over the budget
    _bmp_header(tmp_path / "d.png", 20000, 20000)      # over PIL's own refusal (179 MP)
    with warnings.catch_warnings():
        warnings.simplefilter("error")                  # any warning fails the test
        assert image_size(tmp_path / "a.png") == (10000, 9500)
        assert image_size(tmp_path / "b.png") == (10000, 9500)
        with pytest.raises(InputError, match=r"c\.png: refused: image is 12000x9000, more than the 100000000"):
            image_size(tmp_path / "c.png")
        with pytest.raises(InputError, match=r"d\.png: refused: more than 100000000 pixels"):
            image_size(tmp_path / "d.png")


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES, ids=[h.name for h in CASES])
def test_hostile_data_battery(case):
    """Each hostile:data case through the battery's own runner (gsbench.commands.hostile.run_hostile)."""
    r = run_hostile(case)
    assert r.passed, r.note
