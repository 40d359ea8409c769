"""The few-view split (train.views): RegNeRF's rule on hand-worked cases, every reader's view order,
the config rule, the run id and results.json's record of the split."""
from __future__ import annotations

import json

import numpy as np
import pytest

from gsbench.camera import Camera
from gsbench.config import config_key, load_config, run_id
from gsbench.datasets import load_scene
from gsbench.datasets.colmap import write_colmap
from gsbench.datasets.imageio import write_png
from gsbench.datasets.llff import write_poses_bounds
from gsbench.datasets.splits import split_ids, split_record, spread
from gsbench.errors import InputError

W, H = 8, 6


def _cfg(views=None, holdout="every-8") -> dict:
    return {"train": {"holdout": holdout, "views": views}}


def _cameras(names: list[str]) -> list[Camera]:
    """Distinct poses along x, one per name, looking down +z."""
    K = np.array([[10.0, 0, W / 2], [0, 10.0, H / 2], [0, 0, 1]])
    cams = []
    for k, name in enumerate(names):
        w2c = np.eye(4)
        w2c[0, 3] = -0.1 * k
        cams.append(Camera(K, w2c, W, H, name=name))
    return cams


def _write_images(folder, names: list[str]) -> None:
    for k, name in enumerate(names):
        write_png(folder / name, np.full((H, W, 3), k / 32.0, np.float32))


def _llff_scene(root, n: int):
    names = [f"img_{i:03d}.png" for i in range(n)]
    _write_images(root / "images", names)
    write_poses_bounds(root / "poses_bounds.npy", _cameras(names), np.tile([0.5, 9.0], (n, 1)))
    return load_scene(root, "llff")


# ------------------------------------------------------------------------------ the rule
def test_twenty_views_three_train_1_10_19_test_0_8_16(tmp_path):
    """The literature's example: 20 images, every 8th held out, N = 3."""
    scene = _llff_scene(tmp_path, 20)
    assert split_ids(scene, _cfg(3)) == ([1, 10, 19], [0, 8, 16])


def test_null_and_all_train_on_every_view_the_holdout_leaves(tmp_path):
    scene = _llff_scene(tmp_path, 20)
    rest = [1, 2, 3, 4, 5, 6, 7, 9, 10, 11, 12, 13, 14, 15, 17, 18, 19]
    assert split_ids(scene, _cfg(None)) == (rest, [0, 8, 16])
    assert split_ids(scene, {"train": {}}) == (rest, [0, 8, 16])     # a config from before the key
    assert split_ids(scene, _cfg(17)) == (rest, [0, 8, 16])


def test_too_many_views_is_an_error_naming_both_numbers(tmp_path):
    scene = _llff_scene(tmp_path, 20)
    with pytest.raises(InputError, match=r"train.views=18 but only 17 views"):
        split_ids(scene, _cfg(18))
    with pytest.raises(InputError, match=r"train.views=21 but only 20 views .*holdout=none"):
        split_ids(scene, _cfg(21, "none"))


def test_holdout_none_takes_the_views_over_every_view(tmp_path):
    """linspace(0, 19, 3) = 0, 9.5, 19: 9.5 rounds to even (10); nothing is held out."""
    scene = _llff_scene(tmp_path, 20)
    assert split_ids(scene, _cfg(3, "none")) == ([0, 10, 19], [])
    assert split_ids(scene, _cfg(None, "none")) == (list(range(20)), [])


def test_halves_round_to_even_as_the_references_do():
    """RegNeRF / FreeNeRF: [round(i) for i in np.linspace(...)]; astype(int) would give 1 and 7."""
    assert spread([10, 11, 12, 13], 3) == [10, 12, 13]                 # 0, 1.5, 3
    assert spread(list(range(6)), 3) == [0, 2, 5]                      # 0, 2.5, 5 (half-up would give 3)
    assert spread(list(range(21)), 9) == [0, 2, 5, 8, 10, 12, 15, 18, 20]
    assert spread([4, 9], 1) == [4]


@pytest.mark.parametrize("bad", [0, -2, True, 2.5, "3"])
def test_bad_views_value_is_an_input_error(tmp_path, bad):
    scene = _llff_scene(tmp_path, 9)
    with pytest.raises(InputError, match="train.views"):
        split_ids(scene, _cfg(bad))


@pytest.mark.parametrize("bad", ["train.views=0", "train.views=2.5", "train.views=few"])
def test_config_rule_refuses_bad_views(bad):
    with pytest.raises(InputError, match="train.views"):
        load_config("vanilla", None, [bad])


def test_config_rule_takes_an_integer_or_null():
    assert load_config("vanilla", None, ["train.views=3"])["train"]["views"] == 3
    assert load_config("vanilla", None, ["train.views=3.0"])["train"]["views"] == 3
    assert load_config("vanilla", None, ["train.views=null"])["train"]["views"] is None
    assert load_config("vanilla", None)["train"]["views"] is None


# ------------------------------------------------------------------------------ run ids
def test_run_id_is_unchanged_while_views_is_null_and_changes_when_set():
    """A config without the key (as every config before it) and one with its null default hash alike,
    so stored run ids stay valid; a set value is part of the identity."""
    cfg = load_config("gaussiands", "cpu-small")
    old = json.loads(json.dumps(cfg))
    del old["train"]["views"]
    assert run_id(cfg, "fp") == run_id(old, "fp") and config_key(cfg) == config_key(old)
    few = load_config("gaussiands", "cpu-small", ["train.views=3"])
    six = load_config("gaussiands", "cpu-small", ["train.views=6"])
    assert len({run_id(cfg, "fp"), run_id(few, "fp"), run_id(six, "fp")}) == 3
    assert config_key(few) != config_key(cfg)


# ------------------------------------------------------------------------------ reader order
# Twelve views written out of name order; each reader must give them in name order, so the every-8
# hold-out is view 0 and 8, the pool the other ten, and N = 3 takes pool positions 0, 4.5 -> 4, 9.
NAMES = [f"img_{i:03d}.png" for i in range(12)]
SHUFFLED = [7, 2, 11, 0, 5, 9, 1, 4, 10, 3, 8, 6]
PICKED = ["img_001.png", "img_005.png", "img_011.png"]


def _check_order_and_pick(scene, names: list[str], picked: list[str]) -> None:
    assert [c.name for c in scene.cameras] == names
    trained, held = split_ids(scene, _cfg(3))
    assert [scene.cameras[i].name for i in trained] == picked
    assert [scene.cameras[i].name for i in held] == [names[0], names[8]]


def test_colmap_reader_orders_views_by_name(tmp_path):
    cams = _cameras(NAMES)
    _write_images(tmp_path / "images", NAMES)
    pts = np.random.default_rng(0).normal(size=(20, 3)) + [0, 0, 5]
    write_colmap(tmp_path / "sparse" / "0", [cams[k] for k in SHUFFLED], [NAMES[k] for k in SHUFFLED],
                 pts, np.full((20, 3), 0.5))
    _check_order_and_pick(load_scene(tmp_path, "colmap"), NAMES, PICKED)


def test_llff_reader_orders_views_by_name(tmp_path):
    _write_images(tmp_path / "images", [NAMES[k] for k in SHUFFLED])
    write_poses_bounds(tmp_path / "poses_bounds.npy", _cameras(NAMES), np.tile([0.5, 9.0], (12, 1)))
    _check_order_and_pick(load_scene(tmp_path, "llff"), NAMES, PICKED)


def test_nerf_reader_orders_views_by_name(tmp_path):
    _write_images(tmp_path, NAMES)
    frames = [{"file_path": NAMES[k], "transform_matrix": np.eye(4).tolist()} for k in SHUFFLED]
    (tmp_path / "transforms.json").write_text(json.dumps({"fl_x": 10, "frames": frames}))
    _check_order_and_pick(load_scene(tmp_path, "nerf"), NAMES, PICKED)


def test_nerf_split_files_pick_in_the_train_files_order(tmp_path):
    """transforms_train/test.json keep their own split; the N views follow the train file's frames."""
    _write_images(tmp_path, NAMES[:6])
    fr = lambda i: {"file_path": NAMES[i], "transform_matrix": np.eye(4).tolist()}  # noqa: E731
    (tmp_path / "transforms_train.json").write_text(json.dumps({"fl_x": 10, "frames": [fr(i) for i in (4, 1, 3, 5)]}))
    (tmp_path / "transforms_test.json").write_text(json.dumps({"fl_x": 10, "frames": [fr(0), fr(2)]}))
    scene = load_scene(tmp_path)
    trained, held = split_ids(scene, _cfg(2))
    assert [scene.cameras[i].name for i in trained] == [NAMES[4], NAMES[5]]
    assert [scene.cameras[i].name for i in held] == [NAMES[0], NAMES[2]]


def test_kaolin_reader_orders_views_by_number(tmp_path):
    """10_rgb.png comes after 9_rgb.png (by view number, not as text)."""
    views = tmp_path / "views"
    tf = np.eye(4)
    for i in SHUFFLED:
        write_png(views / f"{i}_rgb.png", np.full((H, W, 3), i / 32.0, np.float32))
        write_png(views / f"{i}_semantic.png", np.zeros((H, W), np.uint8))
        tf[3, 0] = 0.1 * i
        md = {"camera_properties": {"tf_mat": tf.tolist(), "focal_length": 24.0, "horizontal_aperture": 20.0}}
        (views / f"{i}_metadata.json").write_text(json.dumps(md))
    names = [f"{i}_rgb.png" for i in range(12)]
    _check_order_and_pick(load_scene(tmp_path, "kaolin"), names, ["1_rgb.png", "5_rgb.png", "11_rgb.png"])


def test_synthetic_scene_orders_views_by_name(tiny_scene):
    """The generated scene (COLMAP + poses_bounds + gsbench_scene.json's explicit split): 8 views, test
    view 0, pool 1..7, N = 3 at pool positions 0, 3, 6."""
    scene = load_scene(tiny_scene)
    names = [f"frame_{i:05d}.png" for i in range(1, 9)]
    assert [c.name for c in scene.cameras] == names
    trained, held = split_ids(scene, _cfg(3))
    assert [names[i] for i in trained] == ["frame_00002.png", "frame_00005.png", "frame_00008.png"]
    assert held == [0]


def test_every_scene_preset_leaves_room_for_the_protocol():
    """At least 24 views: 21 after the every-8 hold-out, more than RegNeRF's largest N (9)."""
    from gsbench.datasets.synthetic_spec import PRESETS
    assert {name: p["views"] >= 24 for name, p in PRESETS.items()} == {name: True for name in PRESETS}


# ------------------------------------------------------------------------------ results.json
def test_split_record_names_the_views(tmp_path):
    scene = _llff_scene(tmp_path, 20)
    rec = split_record(scene, _cfg(3))
    assert rec == {"holdout": "every-8", "views": 3, "trained_ids": [1, 10, 19],
                   "trained_names": ["img_001.png", "img_010.png", "img_019.png"], "held_out_ids": [0, 8, 16],
                   "held_out_names": ["img_000.png", "img_008.png", "img_016.png"]}


def test_results_json_records_the_trained_and_held_out_views(tiny_scene, tmp_path):
    """A 2-step few-view run on the tiny scene (8 views): trained on views 1, 4, 7, view 0 held out."""
    from tiny import TINY_TRAIN_ARGS

    from gsbench.cli import main
    run = tmp_path / "few"
    assert main(["train", *TINY_TRAIN_ARGS, "--set", "train.views=3", "--scene", str(tiny_scene),
                 "--out", str(run)]) == 0
    assert main(["eval", str(run), "--no-progress"]) == 0
    res = json.loads((run / "results.json").read_text())
    assert res["split"]["views"] == 3 and res["split"]["holdout"] == "every-8"
    assert res["split"]["trained_ids"] == [1, 4, 7] and res["split"]["held_out_ids"] == [0]
    assert res["split"]["trained_names"] == ["frame_00002.png", "frame_00005.png", "frame_00008.png"]
    assert res["split"]["held_out_names"] == ["frame_00001.png"] == res["view_names"]
    assert json.loads((run / "config.json").read_text())["train"]["views"] == 3
