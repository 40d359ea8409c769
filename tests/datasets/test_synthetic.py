"""Synthetic generator: geometry against analytic surfaces, cross-view consistency, layout round trips."""
from __future__ import annotations

import time

import numpy as np
import pytest

from gsbench.datasets import load_scene, scene_fingerprint
from gsbench.datasets.ovs import label_masks
from gsbench.datasets.synthetic import WALL_Y, compose, make_scene, render_view
from gsbench.errors import InputError


@pytest.fixture(scope="module")
def gen(tmp_path_factory):
    out = tmp_path_factory.mktemp("syn") / "tabletop"
    t0 = time.perf_counter()
    make_scene("tabletop-small", out, seed=7)
    print(f"\ntabletop-small generated in {time.perf_counter() - t0:.2f} s")
    return out, compose("tabletop-small", seed=7)


def _backproject(cam, depth):
    """World points of all pixels with depth > 0 (pixel centres at +0.5), and their (row, col)."""
    r, c = np.nonzero(depth > 0)
    z = depth[r, c].astype(np.float64)
    pc = np.stack([(c + 0.5 - cam.cx) / cam.fx * z, (r + 0.5 - cam.cy) / cam.fy * z, z], 1)
    c2w = cam.camera_to_world
    return pc @ c2w[:3, :3].T + c2w[:3, 3], r, c


def test_preset_contents(gen):
    out, spec = gen
    s = load_scene(out)
    assert s.layout == "3dovs+lerf"
    assert all(s.parts().values()), s.parts()
    assert len(s.cameras) == 24 and (s.cameras[0].width, s.cameras[0].height) == (128, 96)
    objects = [p for p in spec.prims if p.kind in ("sphere", "box", "cylinder")]
    assert 3 <= len(objects) <= 8 and len({p.name for p in objects}) == len(objects)
    assert {"floor", "wall", "poster"} <= set(s.class_names) and s.class_names == sorted(s.class_names)
    assert "poster" in s.queries and "floor" not in s.queries
    assert sorted(s.removable_instances) == sorted(p.instance for p in objects)
    assert s.test_ids == [0, 8, 16] and sorted(s.train_ids + s.test_ids) == list(range(24))
    # most pixels see something, and every object is seen in most views
    cover = np.mean([(s.gt_instances(i) >= 0).mean() for i in range(len(s))])
    assert cover > 0.98
    for p in objects:
        seen = np.mean([(s.gt_instances(i) == p.instance).sum() > 20 for i in range(len(s))])
        assert seen > 0.7, p.name


def test_depth_lies_on_analytic_surfaces(gen):
    """Back-projected GT depth (through the loaded Camera, not the generator's rays) lands on the
    surface its instance says: floor z = 0, wall y = WALL_Y, spheres |X - c| = r, cylinders r / h."""
    out, spec = gen
    s = load_scene(out)
    by_inst = {p.instance: p for p in spec.prims}
    poster = next(d for d in spec.decals if d.name == "poster")
    for i in (1, 9, 17):
        X, r, c = _backproject(s.cameras[i], s.gt_depth(i))
        inst = s.gt_instances(i)[r, c]
        for k, p in by_inst.items():
            P = X[inst == k]
            if not len(P):
                continue
            if p.kind == "floor":
                np.testing.assert_allclose(P[:, 2], 0, atol=2e-5)
            elif p.kind == "wall":
                np.testing.assert_allclose(P[:, 1], WALL_Y, atol=2e-5)
            elif p.kind == "sphere":
                np.testing.assert_allclose(np.linalg.norm(P - p.center, axis=1), p.size[0], atol=2e-5)
            elif p.kind == "cylinder":
                rad = np.hypot(P[:, 0] - p.center[0], P[:, 1] - p.center[1])
                on = np.isclose(rad, p.size[0], atol=2e-5) | np.isclose(P[:, 2], p.size[1], atol=2e-5)
                assert on.all()
        # the poster is texture only: its pixels are on the wall plane, no depth edge
        P = X[inst == poster.instance]
        assert len(P) > 50
        np.testing.assert_allclose(P[:, 1], WALL_Y, atol=2e-5)


def _reprojection_median(s, i, j, cj=None):
    """Median relative error between view i's depth carried into view j and view j's depth, where
    the four pixels around the projection carry the source pixel's instance (same visible surface)."""
    X, r, c = _backproject(s.cameras[i], s.gt_depth(i))
    src_inst = s.gt_instances(i)[r, c]
    cj = cj or s.cameras[j]
    dj, ij = s.gt_depth(j).astype(np.float64), s.gt_instances(j)
    uv, z = cj.project(X)
    x, y = uv[:, 0] - 0.5, uv[:, 1] - 0.5  # continuous index of pixel centres
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    ok = (x0 >= 0) & (y0 >= 0) & (x0 + 1 < cj.width) & (y0 + 1 < cj.height) & (z > 0)
    x, y, x0, y0, z, src_inst = x[ok], y[ok], x0[ok], y0[ok], z[ok], src_inst[ok]
    nb = [(y0, x0), (y0, x0 + 1), (y0 + 1, x0), (y0 + 1, x0 + 1)]
    same = np.all([ij[a, b] == src_inst for a, b in nb], axis=0) & np.all([dj[a, b] > 0 for a, b in nb], axis=0)
    fx, fy = x - x0, y - y0
    inv = [1.0 / np.maximum(dj[a, b], 1e-12) for a, b in nb]  # 1/z is bilinear in pixels on a plane
    inv_i = (inv[0] * (1 - fx) * (1 - fy) + inv[1] * fx * (1 - fy) + inv[2] * (1 - fx) * fy + inv[3] * fx * fy)
    assert same.sum() > 1000
    return float(np.median(np.abs(z[same] * inv_i[same] - 1.0)))


def test_reprojection_consistency(gen):
    """GT depth of view i, back-projected and moved into view j, matches view j's GT depth."""
    from gsbench.camera import Camera

    out, _ = gen
    s = load_scene(out)
    meds = [_reprojection_median(s, i, j) for i, j in [(1, 2), (5, 7), (10, 13), (3, 20), (22, 23)]]
    print(f"reprojection median relative depth error per pair: {[f'{m:.2e}' for m in meds]}")
    assert max(meds) < 1e-3
    # control: the same check with view j's camera moved 5 cm along its axis fails
    cj = s.cameras[2]
    w2c = cj.world_to_camera.copy()
    w2c[2, 3] += 0.05
    moved = _reprojection_median(s, 1, 2, Camera(cj.K, w2c, cj.width, cj.height))
    print(f"control (view 2 moved 5 cm): {moved:.2e}")
    assert moved > 1e-2


@pytest.mark.parametrize("layout", ["colmap", "llff", "3dovs", "lerf", "both"])
def test_layout_round_trip_cameras(gen, layout):
    out, spec = gen
    s = load_scene(out, layout=layout)
    assert len(s.cameras) == len(spec.cameras)
    for a, b in zip(spec.cameras, s.cameras):
        np.testing.assert_allclose(b.world_to_camera, a.world_to_camera, atol=1e-6)
        np.testing.assert_allclose(b.K, a.K, atol=1e-6)
        assert (b.width, b.height) == (a.width, a.height)


def test_label_masks_round_trip(gen):
    """3D-OVS class PNGs and LERF polygons read back to exactly the ray-cast class masks."""
    out, spec = gen
    s = load_scene(out)
    lut = {k: v for k, v in spec.instance_classes.items()}
    for i in range(0, len(s), 5):
        ref_inst = render_view(spec, spec.cameras[i])["instances"]
        ref_cls = np.vectorize(lambda k: lut.get(int(k), -1))(ref_inst)
        assert np.array_equal(s.gt_instances(i), ref_inst)
        assert np.array_equal(s.gt_classes(i), ref_cls)
        lm = label_masks(s.gt_labels(i), s.cameras[i].height, s.cameras[i].width, "fillpoly")
        for q in s.queries:
            ref = ref_cls == s.class_names.index(q)
            assert np.array_equal(lm.get(q, np.zeros_like(ref)), ref), (i, q)


def test_removal_ground_truth(gen):
    out, spec = gen
    s = load_scene(out)
    i = 4
    img, inst = s.image(i), s.gt_instances(i)
    for k in s.removable_instances:
        rem = s.removed_image(i, k)
        assert np.array_equal(rem[inst != k], img[inst != k])
        if (inst == k).sum() > 20:
            assert np.abs(rem[inst == k] - img[inst == k]).max() > 0.05
    assert s.removed_image(i, max(s.instance_classes)) is None  # floor / wall / decals are not removable


def test_points_on_visible_surfaces(gen):
    """Sparse points project into train views at the GT depth (to pixel-rounding tolerance)."""
    out, _ = gen
    s = load_scene(out)
    assert 1000 <= len(s.points) <= 5000
    assert s.points[:, 2].min() > -1e-6 and s.points[:, 1].max() < WALL_Y + 1e-6
    cam = s.cameras[s.train_ids[0]]
    uv, z = cam.project(s.points)
    u, v = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
    ok = (u >= 0) & (v >= 0) & (u < cam.width) & (v < cam.height) & (z > 0)
    d = s.gt_depth(s.train_ids[0])[v[ok], u[ok]]
    close = np.abs(d - z[ok]) < 0.01 * z[ok]
    assert close.mean() > 0.5  # the rest are hidden in this view


def test_seeded_and_other_layouts(tmp_path):
    a = make_scene("tabletop-small", tmp_path / "a", seed=1, views=6, resolution=(48, 36), layout="3dovs")
    b = make_scene("tabletop-small", tmp_path / "b", seed=1, views=6, resolution=(48, 36), layout="lerf")
    c = make_scene("tabletop-small", tmp_path / "c", seed=2, views=6, resolution=(48, 36), layout="lerf")
    sa, sb = load_scene(a), load_scene(b)
    assert sa.layout == "3dovs" and not sa.has_labels and sa.has_semantics
    assert sb.layout == "lerf" and sb.has_labels and not sb.has_semantics and sb.has_depth
    for i in range(6):
        assert np.array_equal(sa.image(i), sb.image(i))
    assert scene_fingerprint(b) != scene_fingerprint(c)
    with pytest.raises(InputError, match="not an empty folder"):
        make_scene("tabletop-small", a, seed=1, views=6)
    with pytest.raises(InputError, match="unknown preset"):
        make_scene("castle", tmp_path / "d")


def test_fingerprint_content_not_path(gen, tmp_path):
    import shutil

    out, _ = gen
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    assert scene_fingerprint(copy) == scene_fingerprint(out)
    img = copy / "images" / "frame_00003.png"
    from gsbench.datasets.imageio import read_rgb, write_png

    x = read_rgb(img)
    x[0, 0] = 1.0 - x[0, 0]
    write_png(img, x)
    assert scene_fingerprint(copy) != scene_fingerprint(out)


def test_cli_make_scene(tmp_path, capsys):
    from gsbench.cli import main

    out = tmp_path / "cli"
    args = ["make-scene", "--preset", "tabletop-small", "--out", str(out), "--views", "4", "--seed", "3", "--quiet"]
    assert main(args + ["--resolution", "40x30"]) == 0
    assert "4 views 40x30" in capsys.readouterr().out
    s = load_scene(out)
    assert len(s) == 4 and s.cameras[0].width == 40
    assert main(args + ["--resolution", "40x30"]) == 1
    assert "not an empty folder" in capsys.readouterr().err
    assert main(args[:4] + [str(tmp_path / "x"), "--resolution", "40by30"]) == 1
    assert "--resolution" in capsys.readouterr().err
