"""Scene readers: conventions against hand-computed projections, round trips, bad input, real data."""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from paths import SHARED_DATA

from gsbench.camera import Camera
from gsbench.datasets import load_scene, scene_fingerprint
from gsbench.datasets.colmap import write_colmap
from gsbench.datasets.imageio import write_png
from gsbench.datasets.llff import write_poses_bounds
from gsbench.datasets.ovs import label_masks, mask_to_polygons, polygons_to_mask, read_lerf_label
from gsbench.errors import InputError

SHARED = SHARED_DATA
KAOLIN = SHARED / "kaolin_clock"
LERF_FILE = SHARED / "lerf_ovs_labels" / "waldo_kitchen" / "frame_00066.json"
need_kaolin = pytest.mark.skipif(
    not KAOLIN.is_dir(), reason=f"real test data absent: {KAOLIN} (../shared/data not beside the repo)"
)
need_lerf = pytest.mark.skipif(
    not LERF_FILE.is_file(), reason=f"real test data absent: {LERF_FILE} (../shared/data not beside the repo)"
)


def _images(folder: Path, n: int, w: int = 16, h: int = 12) -> list[str]:
    names = [f"img_{i:03d}.png" for i in range(n)]
    for i, nm in enumerate(names):
        write_png(folder / nm, np.full((h, w, 3), i / max(n, 1), np.float32))
    return names


def _random_cameras(n: int, w: int = 16, h: int = 12, seed: int = 0) -> list[Camera]:
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    cams = []
    for i in range(n):
        w2c = np.eye(4)
        w2c[:3, :3] = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
        w2c[:3, 3] = rng.normal(0, 2, 3)
        K = np.array([[20.0 + i, 0, w / 2], [0, 20.0 + i, h / 2], [0, 0, 1]])
        cams.append(Camera(K, w2c, w, h, name=f"img_{i:03d}.png"))
    return cams


# ------------------------------------------------------------------------------ conventions
def test_llff_columns_down_right_back(tmp_path):
    """A hand-written LLFF pose: camera at (0, 0, 5) looking along world -z with world +y up.
    LLFF columns are [down, right, back] = [-y, +x, +z]."""
    _images(tmp_path / "images", 1, 40, 30)
    m = np.zeros((3, 5))
    m[:, 0] = [0, -1, 0]   # down
    m[:, 1] = [1, 0, 0]    # right
    m[:, 2] = [0, 0, 1]    # back
    m[:, 3] = [0, 0, 5]    # centre
    m[:, 4] = [30, 40, 50]  # H, W, focal
    np.save(tmp_path / "poses_bounds.npy", np.concatenate([m.ravel(), [1, 10]])[None])
    cam = load_scene(tmp_path, "llff").cameras[0]
    np.testing.assert_allclose(cam.center, [0, 0, 5], atol=1e-12)
    uv, z = cam.project(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float))
    np.testing.assert_allclose(z, [5, 5, 5])
    np.testing.assert_allclose(uv[0], [20, 15])           # image centre
    np.testing.assert_allclose(uv[1], [20 + 50 / 5, 15])  # +x world -> right
    np.testing.assert_allclose(uv[2], [20, 15 - 50 / 5])  # +y world (up) -> up in the image


def test_llff_scales_focal_to_image_size(tmp_path):
    _images(tmp_path / "images", 1, 20, 15)  # half of the 40 x 30 the poses describe
    m = np.zeros((3, 5))
    m[:, :3] = np.eye(3)
    m[:, 4] = [30, 40, 50]
    np.save(tmp_path / "poses_bounds.npy", np.concatenate([m.ravel(), [1, 10]])[None])
    cam = load_scene(tmp_path, "llff").cameras[0]
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (25.0, 25.0, 10.0, 7.5)


def test_llff_round_trip(tmp_path):
    cams = [Camera(np.array([[30.0, 0, 8], [0, 30.0, 6], [0, 0, 1]]), c.world_to_camera, 16, 12, c.name)
            for c in _random_cameras(5)]
    _images(tmp_path / "images", 5)
    write_poses_bounds(tmp_path / "poses_bounds.npy", cams, np.tile([0.5, 9.0], (5, 1)))
    got = load_scene(tmp_path, "llff").cameras
    for a, b in zip(cams, got):
        np.testing.assert_allclose(b.world_to_camera, a.world_to_camera, atol=1e-10)
        np.testing.assert_allclose(b.K, a.K, atol=1e-12)


def test_transforms_json_opengl_to_opencv(tmp_path):
    """Identity OpenGL c2w: camera at the origin looking down -z with +y up."""
    _images(tmp_path, 1, 40, 30)
    angle = 2 * math.atan(20 / 50)  # fx = 0.5 W / tan(angle / 2) = 50
    tj = {
        "camera_angle_x": angle,
        "k1": 0.1,
        "frames": [{"file_path": "./img_000", "transform_matrix": np.eye(4).tolist()}],
    }
    (tmp_path / "transforms.json").write_text(json.dumps(tj))
    s = load_scene(tmp_path)
    assert s.layout == "nerf"
    cam = s.cameras[0]
    assert cam.fx == pytest.approx(50.0) and cam.fy == pytest.approx(50.0)
    assert cam.meta["distortion"] == {"k1": 0.1}
    uv, z = cam.project(np.array([[0, 0, -2], [1, 0, -2], [0, 1, -2]], float))
    np.testing.assert_allclose(z, [2, 2, 2])
    np.testing.assert_allclose(uv, [[20, 15], [45, 15], [20, -10]])


def test_transforms_split_files(tmp_path):
    _images(tmp_path, 3)
    fr = lambda i: {"file_path": f"img_{i:03d}.png", "transform_matrix": np.eye(4).tolist()}  # noqa: E731
    (tmp_path / "transforms_train.json").write_text(json.dumps({"fl_x": 20, "frames": [fr(0), fr(2)]}))
    (tmp_path / "transforms_test.json").write_text(json.dumps({"fl_x": 20, "frames": [fr(1)]}))
    s = load_scene(tmp_path)
    assert s.train_ids == [0, 1] and s.test_ids == [2]
    assert [Path(p).name for p in s.image_paths] == ["img_000.png", "img_002.png", "img_001.png"]


@pytest.mark.parametrize("binary", [True, False])
def test_colmap_round_trip_binary_and_text(tmp_path, binary):
    cams = _random_cameras(4)
    _images(tmp_path / "images", 4)
    pts = np.random.default_rng(1).normal(size=(30, 3))
    cols = np.random.default_rng(2).random((30, 3))
    write_colmap(tmp_path / "sparse" / "0", cams, [c.name for c in cams], pts, cols, binary=binary)
    assert (tmp_path / "sparse" / "0" / ("cameras.bin" if binary else "cameras.txt")).is_file()
    s = load_scene(tmp_path)
    assert s.layout == "colmap"
    for a, b in zip(cams, s.cameras):
        np.testing.assert_allclose(b.world_to_camera, a.world_to_camera, atol=1e-9)
        np.testing.assert_allclose(b.K, a.K, atol=1e-9)
    np.testing.assert_allclose(s.points, pts, atol=1e-9)
    np.testing.assert_allclose(s.point_colors, np.round(cols * 255) / 255, atol=1e-9)
    assert s.test_ids == [0] and s.train_ids == [1, 2, 3]  # LLFF hold-out: index % 8 == 0
    img = s.image(2)
    assert img.dtype == np.float32 and img.shape == (12, 16, 3)
    np.testing.assert_allclose(img, round(2 / 4 * 255) / 255, atol=1e-6)


# ------------------------------------------------------------------------------ bad input
def test_missing_image_names_the_file(tmp_path):
    cams = _random_cameras(3)
    _images(tmp_path / "images", 3)
    write_colmap(tmp_path / "sparse" / "0", cams, [c.name for c in cams])
    (tmp_path / "images" / "img_001.png").unlink()
    with pytest.raises(InputError, match="img_001.png"):
        load_scene(tmp_path)


def test_image_size_mismatch_names_the_file(tmp_path):
    cams = _random_cameras(2)
    _images(tmp_path / "images", 2)
    write_png(tmp_path / "images" / "img_001.png", np.zeros((10, 10, 3), np.float32))
    write_colmap(tmp_path / "sparse" / "0", cams, [c.name for c in cams])
    with pytest.raises(InputError, match="img_001.png.*10x10"):
        load_scene(tmp_path)


def test_pose_count_mismatch_names_the_file(tmp_path):
    cams = [
        Camera(np.array([[30.0, 0, 8], [0, 30.0, 6], [0, 0, 1]]), c.world_to_camera, 16, 12) for c in _random_cameras(3)
    ]
    _images(tmp_path / "images", 4)
    write_poses_bounds(tmp_path / "poses_bounds.npy", cams, np.tile([0.5, 9.0], (3, 1)))
    with pytest.raises(InputError, match="poses_bounds.npy: 3 poses but 4 images"):
        load_scene(tmp_path)


def _ovs_scene(root: Path) -> None:
    cams = [
        Camera(np.array([[30.0, 0, 8], [0, 30.0, 6], [0, 0, 1]]), c.world_to_camera, 16, 12) for c in _random_cameras(3)
    ]
    _images(root / "images", 3)
    write_poses_bounds(root / "poses_bounds.npy", cams, np.tile([0.5, 9.0], (3, 1)))
    seg = root / "segmentations"
    seg.mkdir()
    (seg / "classes.txt").write_text("mug\nbanana\n")
    m = np.zeros((12, 16), np.uint8)
    m[2:5, 3:9] = 255
    write_png(seg / "1" / "mug.png", m)
    b = np.zeros((12, 16), np.uint8)
    b[4:8, 7:12] = 255
    write_png(seg / "1" / "banana.png", b)


def test_3dovs_classes_sorted_overlap_unlabelled(tmp_path):
    _ovs_scene(tmp_path)
    s = load_scene(tmp_path)
    assert s.layout == "3dovs" and s.class_names == ["banana", "mug"]
    assert s.semantic_view_ids == [1] and s.gt_classes(0) is None
    c = s.gt_classes(1)
    assert c[3, 4] == 1 and c[6, 10] == 0 and c[0, 0] == -1
    assert c[4, 7] == -1  # claimed by both masks
    masks = s.gt_class_masks(1)
    assert masks["mug"][4, 7] and masks["banana"][4, 7]


def test_unknown_class_file_names_the_file(tmp_path):
    _ovs_scene(tmp_path)
    write_png(tmp_path / "segmentations" / "1" / "teapot.png", np.zeros((12, 16), np.uint8))
    with pytest.raises(InputError, match="teapot.png"):
        load_scene(tmp_path)


def test_corrupt_label_json_names_the_file(tmp_path):
    cams = _random_cameras(2)
    _images(tmp_path / "images", 2)
    write_colmap(tmp_path / "sparse" / "0", cams, [c.name for c in cams])
    lab = tmp_path / "label" / tmp_path.name
    lab.mkdir(parents=True)
    (lab / "frame_00001.json").write_text('{"objects": [{"category": "mug", "segmentation": [[1, 2], ')
    with pytest.raises(InputError, match="frame_00001.json: corrupt"):
        load_scene(tmp_path)


def test_unknown_layout_is_an_error(tmp_path):
    with pytest.raises(InputError, match="unknown scene layout"):
        load_scene(tmp_path)
    with pytest.raises(InputError, match="unknown layout"):
        load_scene(tmp_path, layout="blender")


# ------------------------------------------------------------------------------ polygons
def test_mask_to_polygons_is_exact_with_holes_and_thin_parts():
    rng = np.random.default_rng(0)
    m = np.zeros((40, 50), bool)
    m[5:30, 5:40] = True
    m[10:15, 10:20] = False       # a hole
    m[33, 2:45] = True            # a one-pixel line
    m[36:39, 40:48] = rng.random((3, 8)) > 0.4
    polys = mask_to_polygons(m)
    assert np.array_equal(polygons_to_mask(polys, 40, 50, "fillpoly"), m)


def test_centre_rasterisation_of_a_square():
    sq = [np.array([[2.0, 3.0], [6.0, 3.0], [6.0, 8.0], [2.0, 8.0]])]
    m = polygons_to_mask(sq, 12, 12, "centre")
    assert m.sum() == 4 * 5 and m[3:8, 2:6].all()
    assert polygons_to_mask(sq, 12, 12, "fillpoly").sum() == 5 * 6  # fillPoly includes the boundary pixels


# ------------------------------------------------------------------------------ real data
@need_lerf
def test_real_lerf_label_areas():
    """Each object's pixel area against its `area` field (the polygon area)."""
    info, objs = read_lerf_label(LERF_FILE)
    H, W = info["height"], info["width"]
    assert (W, H) == (985, 725) and len(objs) == 4
    assert {o.category for o in objs} == {"plastic ladle", "refrigerator", "pot", "spatula"}
    errs = {}
    for o in objs:
        m = polygons_to_mask(o.polygons, H, W, "centre")
        errs[o.category] = abs(m.sum() - o.area) / o.area
        x1, y1, x2, y2 = o.bbox
        ys, xs = np.nonzero(polygons_to_mask(o.polygons, H, W, "fillpoly"))
        assert (xs.min(), ys.min(), xs.max(), ys.max()) == (x1, y1, x2, y2)
    print("LERF area relative errors (centre rasterisation):", {k: round(v, 5) for k, v in errs.items()})
    assert max(errs.values()) < 0.02


@need_lerf
def test_real_lerf_frame_index_and_rescale(tmp_path):
    """frame_00066 is index 65; labels drawn at 985x725 are rescaled to 197x145 images."""
    n = 70
    cams = [
        Camera(
            np.array([[100.0, 0, 98.5], [0, 100.0, 72.5], [0, 0, 1]]), c.world_to_camera, 197, 145, f"img_{i:03d}.png"
        )
        for i, c in enumerate(_random_cameras(n))
    ]
    _images(tmp_path / "images", n, 197, 145)
    write_colmap(tmp_path / "sparse" / "0", cams, [c.name for c in cams])
    (tmp_path / "label" / tmp_path.name).mkdir(parents=True)
    shutil.copy(LERF_FILE, tmp_path / "label" / tmp_path.name / "frame_00066.json")
    s = load_scene(tmp_path)
    assert s.layout == "lerf" and s.label_view_ids == [65]
    assert s.queries == ["plastic ladle", "pot", "refrigerator", "spatula"]
    assert s.gt_labels(64) is None and s.gt_labels(66) is None
    labs = s.gt_labels(65)
    fridge = next(o for o in labs if o.category == "refrigerator")
    assert fridge.bbox == pytest.approx((0.0, 339 / 5, 196 / 5, 723 / 5))
    m = label_masks(labs, 145, 197, "centre")["refrigerator"]
    assert abs(m.sum() - 71491.5 / 25) / (71491.5 / 25) < 0.03


@need_kaolin
def test_kaolin_clock_visual_hull_reprojects():
    """Carve a visual hull from the train silhouettes; ray-cast it into the held-out views."""
    s = load_scene(KAOLIN)
    assert s.layout == "kaolin" and len(s.cameras) == 100
    assert s.cameras[0].fx == pytest.approx(256 * 24 / 20.955, rel=1e-4)
    assert len(s.test_ids) >= 10
    B, n = 50.0, 64  # the clock sits at the origin, within +-50 units
    vox = 2 * B / n
    g = (np.arange(n) + 0.5) * vox - B
    X = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    keep = np.ones(len(X), bool)
    for i in s.train_ids:
        cam, sil = s.cameras[i], s.gt_classes(i) == 1
        idx = np.flatnonzero(keep)
        uv, z = cam.project(X[idx])
        u, v = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
        inside = (u >= 0) & (u < cam.width) & (v >= 0) & (v < cam.height) & (z > 0)
        ok = np.ones(len(idx), bool)
        ok[inside] = sil[v[inside], u[inside]]
        keep[idx[~ok]] = False
    occ = keep.reshape(n, n, n)
    assert 0.01 < occ.mean() < 0.5
    r_occ = float(np.linalg.norm(X[keep], axis=1).max()) + vox
    ious = []
    for i in s.test_ids:
        cam = s.cameras[i]
        jj, ii = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
        d = np.stack([(jj - cam.cx) / cam.fx, (ii - cam.cy) / cam.fy, np.ones_like(jj)], -1).reshape(-1, 3)
        D = d @ cam.camera_to_world[:3, :3].T
        D /= np.linalg.norm(D, axis=1, keepdims=True)
        o = cam.center
        dist = np.linalg.norm(o)
        near = np.linalg.norm(o + (D @ -o)[:, None] * D, axis=1) < r_occ  # rays passing the hull's sphere
        Dn = D[near]
        hit_n = np.zeros(len(Dn), bool)
        for t in np.arange(dist - r_occ, dist + r_occ, 0.75 * vox):
            k = np.floor((o + t * Dn + B) / vox).astype(int)
            ins = np.all((k >= 0) & (k < n), 1) & ~hit_n
            hit_n[ins] = occ[k[ins, 0], k[ins, 1], k[ins, 2]]
        hit = np.zeros(len(D), bool)
        hit[near] = hit_n
        hit = hit.reshape(cam.height, cam.width)
        gt = s.gt_classes(i) == 1
        ious.append((hit & gt).sum() / max((hit | gt).sum(), 1))
    print(f"kaolin visual hull: {len(s.train_ids)} carving views, held-out IoU mean {np.mean(ious):.4f} "
          f"min {np.min(ious):.4f} over {len(ious)} views")
    assert np.mean(ious) > 0.8


@need_kaolin
def test_kaolin_images_and_fingerprint(tmp_path):
    s = load_scene(KAOLIN)
    img = s.image(3)
    assert img.shape == (256, 256, 3) and img.dtype == np.float32 and 0 <= img.min() and img.max() <= 1
    assert s.has_semantics and not s.has_depth and not s.has_points
    fp = scene_fingerprint(KAOLIN)
    assert fp == scene_fingerprint(KAOLIN) and len(fp) == 64
