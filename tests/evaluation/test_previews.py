"""Pictures: what `gsbench eval` saves in a run folder (gsbench.preview_files, gsbench.evaluation.previews)
and how the report places them (gsbench.reports.pictures)."""
from __future__ import annotations

import io
import json
import os
import re
import shutil
import stat

import numpy as np
import pytest
from previews_fake import MAGENTA, fake_previews

from gsbench.errors import InputError
from gsbench.preview_files import FRAME_ARRAYS, MANIFEST, PREVIEWS_DIR, read_arrays, read_manifest


# ------------------------------------------------------------------ the file contract
def test_previews_round_trip_and_replace_whole_folder(tmp_path):
    fake_previews(tmp_path, "gaussiands")
    m = read_manifest(tmp_path)
    assert m["previews_version"] == 1 and m["frames"][0]["queries"][1]["iou"] == 1.0
    arr = read_arrays(tmp_path, m["frames"][0], FRAME_ARRAYS)
    assert arr["render"][0, 0].tolist() == list(MAGENTA) and arr["pred"].shape == (2, 12, 16)
    # a second evaluation without semantics replaces everything: the removal file of the first is gone
    fake_previews(tmp_path, "vanilla", semantic=False)
    files = sorted(p.name for p in (tmp_path / PREVIEWS_DIR).iterdir())
    assert files == ["3dovs_frame_00001.npz", MANIFEST]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]   # no temporary folder left


@pytest.mark.parametrize("umask,folder,file", [(0o022, 0o755, 0o644), (0o027, 0o750, 0o640)])
def test_previews_folder_gets_a_new_folders_mode(tmp_path, umask, folder, file):
    """previews/ is staged in a mkdtemp folder (0700): it gets what mkdir would give (the umask's)."""
    old = os.umask(umask)
    try:
        fake_previews(tmp_path, "vanilla", semantic=False)
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / PREVIEWS_DIR).stat().st_mode) == folder
    assert {stat.S_IMODE(f.stat().st_mode) for f in (tmp_path / PREVIEWS_DIR).iterdir()} == {file}


def test_read_arrays_refuses_pickled_objects(tmp_path):
    fake_previews(tmp_path, "gaussiands")
    m = read_manifest(tmp_path)
    path = tmp_path / PREVIEWS_DIR / m["frames"][0]["file"]
    buf = io.BytesIO()
    np.savez(buf, **{n: np.array([{"x": 1}], dtype=object) for n in FRAME_ARRAYS})
    path.write_bytes(buf.getvalue())
    with pytest.raises(InputError, match="not a readable .npz"):
        read_arrays(tmp_path, m["frames"][0], FRAME_ARRAYS)


def test_bad_manifest_and_paths_are_one_line_errors(tmp_path):
    fake_previews(tmp_path, "gaussiands")
    p = tmp_path / PREVIEWS_DIR / MANIFEST
    m = json.loads(p.read_text())
    with pytest.raises(InputError, match="must be a .npz inside"):
        read_arrays(tmp_path, {"file": "../results.json"}, FRAME_ARRAYS)
    (tmp_path / PREVIEWS_DIR / m["frames"][0]["file"]).write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(InputError, match="3dovs_frame_00001.npz"):
        read_arrays(tmp_path, m["frames"][0], FRAME_ARRAYS)
    p.write_text(json.dumps({**m, "previews_version": 99}))
    with pytest.raises(InputError, match="previews_version"):
        read_manifest(tmp_path)
    assert read_manifest(tmp_path / "elsewhere") is None


def test_pick_frames_prefers_held_out_then_spreads():
    from gsbench.evaluation.previews import pick_frames
    sets = {"held-out": [0, 8, 16], "reference": [1, 2, 3, 4, 5]}
    assert pick_frames(sets, 2) == [(0, "held-out"), (16, "held-out")]
    assert pick_frames(sets, 3) == [(0, "held-out"), (8, "held-out"), (16, "held-out")]
    assert pick_frames(sets, 5) == [(0, "held-out"), (8, "held-out"), (16, "held-out"), (1, "reference"),
                                    (5, "reference")]
    assert pick_frames({"held-out": [], "reference": [4, 6, 9]}, 1) == [(4, "reference")]
    assert pick_frames({"held-out": [], "reference": []}, 2) == []


# ------------------------------------------------------------------ pixels of the report
def test_overlay_dims_outside_tints_inside_and_outlines():
    from gsbench.reports.pictures import overlay
    img = np.full((5, 5, 3), 100, np.uint8)
    m = np.zeros((5, 5), bool)
    m[1:4, 1:4] = True
    out = overlay(img, m, (200, 0, 0))
    assert out[0, 0].tolist() == [40, 40, 40]              # 0.4 * 100
    assert out[2, 2].tolist() == [155, 45, 45]             # 0.45 * 100 + 0.55 * (200, 0, 0)
    assert out[1, 1].tolist() == [200, 0, 0]               # edge of the mask: the colour itself


def test_depth_image_scale_and_transparent_pixels():
    from gsbench.reports.pictures import NO_SURFACE, depth_image
    d = np.array([[1.0, 2.0, 3.0, np.nan]])
    a = np.array([[255, 255, 0, 255]])
    out = depth_image(d, a, 1.0, 2.0)
    assert out[0, 2].tolist() == list(NO_SURFACE)          # alpha 0: no surface
    assert out[0, 0].tolist() != out[0, 1].tolist()        # near and far get different colours
    assert out[0, 3].tolist() == out[0, 1].tolist()        # NaN reads as far, never crashes


def test_report_places_pictures_and_names_runs_without_them(tmp_path):
    from report_runs import write_run

    from gsbench.reports import build_report
    runs = tmp_path / "runs"
    g = write_run(runs, "gds", method="gaussiands", scene="bench", metrics={"psnr": 20.0, "miou_3dovs": 0.75})
    v = write_run(runs, "van", method="vanilla", scene="bench", metrics={"psnr": 19.0})
    write_run(runs, "two", method="twostage", scene="bench", metrics={"psnr": 18.0})
    fake_previews(g, "gaussiands")
    fake_previews(v, "vanilla", render_rgb=(0, 255, 0), semantic=False)
    summary = build_report(runs, tmp_path / "report")
    page = summary.index.read_text()
    sec = re.search(r'<section id="pictures">.*?</section>', page, re.S).group(0)
    srcs = re.findall(r'<img src="([^"]+)"', sec)
    # GT row: image, GT depth, 2 GT masks; gaussiands: render, depth, 2 masks; vanilla: render, depth;
    # removal: before, after, GT without it
    assert len(srcs) == 4 + 4 + 2 + 3
    assert all((tmp_path / "report" / s).is_file() for s in srcs) and len(summary.pictures) == len(srcs)
    assert "IoU 50.0 %" in sec and "BIoU 25.0 %" in sec and "PSNR 21.50 dB" in sec and "frame mIoU 75.0 %" in sec
    assert "method vanilla has no semantic field" in sec and "residual 12.5 %" in sec
    assert any("twostage on bench) has no saved previews" in n for n in summary.notes)
    # a broken preview file is named in a note; the other runs are still shown
    shutil.rmtree(v / PREVIEWS_DIR)
    (g / PREVIEWS_DIR / "3dovs_frame_00001.npz").write_bytes(b"garbage")
    summary = build_report(runs, tmp_path / "report")
    assert any("3dovs_frame_00001.npz" in n for n in summary.notes)
    assert not (tmp_path / "report" / "pictures" / "bench" / "vanilla-id-van").exists()   # stale pictures removed


@pytest.mark.slow
def test_eval_saves_previews_that_reproduce_the_scored_numbers(tmp_path):
    """The masks saved for a frame give the IoUs whose mean results.json holds for that frame, in
    the configured query mode: two code paths (scoring, pictures) agree. eval.previews=0 deletes them."""
    from tiny import TINY_SET

    from gsbench.config import load_config, run_id
    from gsbench.datasets.synthetic import make_scene
    from gsbench.evaluation import evaluate_run
    from gsbench.metric_table import seg_metric
    from gsbench.runs import train_run
    from gsbench.store import read_json, write_json_atomic
    scene = make_scene("tabletop-small", tmp_path / "s", seed=0, views=10, resolution=(48, 36))
    run = train_run(load_config("gaussiands", "cpu-small", TINY_SET), scene, tmp_path / "run", progress=False)
    res = evaluate_run(run, progress=False)
    m = read_manifest(run)
    assert m["run_id"] == res["run_id"] and m["query_mode"] == res["query_mode"]
    assert sorted((f["protocol"], f["frame_set"]) for f in m["frames"]) == [
        ("3dovs", "held-out"), ("3dovs", "held-out"), ("lerf", "held-out"), ("lerf", "held-out")]
    for f in m["frames"]:
        names = res["frames"][f"{f['protocol']}/held-out"]
        scored = res["per_view"][seg_metric("miou", f["protocol"], None, "held-out")][names.index(f["view"])]
        ious = [q["iou"] for q in f["queries"] if q["iou"] is not None]
        assert ious and abs(sum(ious) / len(ious) - scored) < 1e-9
        arr = read_arrays(run, f, FRAME_ARRAYS)
        assert arr["render"].shape == (36, 48, 3) and arr["pred"].shape == (len(f["queries"]), 36, 48)
        assert f["scored_size"] == [48, 36] and f["psnr"] > 5.0
    for r in m["removal"]:
        assert 0.0 <= r["residual"] <= 1.0 and r["query"] in read_json(scene / "gsbench_scene.json")["class_names"]
    cfg = read_json(run / "config.json")
    cfg["eval"]["previews"] = 0           # as if trained so: the run's ids follow (eval checks them)
    cfg["run_id"] = run_id(cfg, cfg["scene"]["fingerprint"])
    write_json_atomic(run / "config.json", cfg)
    summary = read_json(run / "train_summary.json")
    summary["run_id"], summary["resolved_config_id"] = cfg["run_id"], run_id(cfg, cfg["scene"]["fingerprint"])
    write_json_atomic(run / "train_summary.json", summary)
    evaluate_run(run, progress=False)
    assert not (run / PREVIEWS_DIR).exists()


def test_vanilla_eval_saves_pictures_without_masks(tiny_run, tmp_path):
    """A run without a semantic field still gets its render and depth, and says why there are no masks."""
    from gsbench.evaluation import evaluate_run
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    evaluate_run(run, progress=False)
    m = read_manifest(run)
    assert m["method"] == "vanilla" and m["frames"] and m["removal"] == []
    assert all(f["queries"] == [] and "no semantic field" in f["semantic_reason"] for f in m["frames"])
    assert "no semantic field" in m["removal_reason"]
    arr = read_arrays(run, m["frames"][0], FRAME_ARRAYS)
    assert arr["render"].dtype == np.uint8 and arr["depth"].dtype == np.float16 and arr["pred"].shape[0] == 0
