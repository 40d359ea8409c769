"""Every CLI entry point turns bad input into a one-line error naming the file and the problem (exit 1).

Each test corrupts a copy of a tiny synthetic scene (or a run folder, grid file, prediction folder)
and checks the exit code, that the error is one line of the form `gsbench CMD: error: ...`, that it
names the offending file and says what is wrong, and that no traceback reaches the user.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from gsbench.cli import main

TRAIN_FAST = ["--preset", "cpu-small", "--set", "train.iterations=2", "--set", "train.eval_every=0", "--no-progress"]


@pytest.fixture(scope="module")
def scene(tiny_scene) -> Path:
    """The session's tiny scene (tests/conftest.py), copied by the tests that corrupt it."""
    return tiny_scene


@pytest.fixture(scope="module")
def trained_run(tiny_run) -> Path:
    """The session's real (2-iteration) vanilla run folder, copied by the tests that corrupt it."""
    return tiny_run


def copy_scene(scene: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "scene"
    shutil.copytree(scene, dst)
    return dst


def cli_error(capsys, argv: list[str]) -> tuple[int, str]:
    """Run the CLI in-process; return (exit code, the error line)."""
    code = main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith(f"gsbench {argv[0]}: error: ")]
    assert len(errors) == 1, f"expected one error line, got stderr:\n{err}"
    # nothing of the message spills onto further lines
    assert lines[-1] == errors[0], f"error is not the last, single line:\n{err}"
    return code, errors[0]


def train_argv(scene: Path, out: Path, method: str = "vanilla", *extra: str) -> list[str]:
    return ["train", "--method", method, "--scene", str(scene), "--out", str(out), *TRAIN_FAST, *extra]


# ------------------------------------------------------------------------------------ images
def test_missing_image(scene, tmp_path, capsys):
    s = copy_scene(scene, tmp_path)
    (s / "images" / "frame_00003.png").unlink()
    code, msg = cli_error(capsys, train_argv(s, tmp_path / "run"))
    assert code == 1
    assert str(s / "images" / "frame_00003.png") in msg and "missing" in msg


def test_unreadable_image_corrupt_png(scene, tmp_path, capsys):
    s = copy_scene(scene, tmp_path)
    (s / "images" / "frame_00003.png").write_bytes(b"this is not a png file")
    code, msg = cli_error(capsys, train_argv(s, tmp_path / "run"))
    assert code == 1
    assert str(s / "images" / "frame_00003.png") in msg and "cannot" in msg


def test_truncated_png(scene, tmp_path, capsys):
    s = copy_scene(scene, tmp_path)
    p = s / "images" / "frame_00004.png"
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    code, msg = cli_error(capsys, train_argv(s, tmp_path / "run"))
    assert code == 1
    assert str(p) in msg and ("cannot decode" in msg or "corrupt" in msg or "truncated" in msg)


def test_wrong_image_size(scene, tmp_path, capsys):
    s = copy_scene(scene, tmp_path)
    p = s / "images" / "frame_00002.png"
    cv2.imwrite(str(p), np.zeros((12, 16, 3), np.uint8))
    code, msg = cli_error(capsys, train_argv(s, tmp_path / "run"))
    assert code == 1
    assert str(p) in msg and "16x12" in msg and "32x24" in msg


def test_pose_image_count_mismatch(scene, tmp_path, capsys):
    s = tmp_path / "llff"
    s.mkdir()
    shutil.copytree(scene / "images", s / "images")
    np.save(s / "poses_bounds.npy", np.load(scene / "poses_bounds.npy")[:-1])   # 7 poses, 8 images
    code, msg = cli_error(capsys, train_argv(s, tmp_path / "run"))
    assert code == 1
    assert str(s / "poses_bounds.npy") in msg and "7 poses" in msg and "8 images" in msg


# ------------------------------------------------------------------------------------ depth prior
@pytest.mark.parametrize("bad", ["nan", "inf"])
def test_nonfinite_depth_prior(scene, tmp_path, capsys, bad):
    """The synthetic scene's GT depth is the depth prior (priors.depth.provider=gt)."""
    s = copy_scene(scene, tmp_path)
    p = s / "gt" / "depth" / "frame_00003.npy"
    d = np.load(p)
    d[2:5, 2:6] = np.nan if bad == "nan" else np.inf
    np.save(p, d)
    code, msg = cli_error(capsys, train_argv(s, tmp_path / "run", "gaussiands", "--set", "semantic.loss=false",
                                             "--set", "gaussiands.losses.ds=false"))
    assert code == 1
    assert str(p) in msg
    assert ("12 NaN" in msg) if bad == "nan" else ("12 inf" in msg)


# ------------------------------------------------------------------------------------ JSON
def test_truncated_lerf_label_json(scene, tmp_path, capsys):
    s = copy_scene(scene, tmp_path)
    p = s / "label" / "tabletop-small" / "frame_00003.json"
    text = p.read_text()
    p.write_text(text[: len(text) // 2])
    code, msg = cli_error(capsys, train_argv(s, tmp_path / "run"))
    assert code == 1
    assert str(p) in msg and "corrupt or truncated JSON" in msg


def test_truncated_lerf_label_json_in_mask_scoring(scene, tmp_path, capsys):
    labels = tmp_path / "labels"
    shutil.copytree(scene / "label" / "tabletop-small", labels)
    p = labels / "frame_00005.json"
    p.write_text(p.read_text()[:40])
    (tmp_path / "pred").mkdir()
    code, msg = cli_error(capsys, ["eval", "--masks", str(tmp_path / "pred"), "--layout", str(labels),
                                   "--protocol", "lerf", "--out", str(tmp_path / "out")])
    assert code == 1
    assert str(p) in msg and "corrupt or truncated JSON" in msg


def test_corrupt_transforms_json(scene, tmp_path, capsys):
    s = tmp_path / "nerf"
    s.mkdir()
    shutil.copytree(scene / "images", s / "images")
    frames = [{"file_path": f"images/frame_{i:05d}", "transform_matrix": np.eye(4).tolist()} for i in range(1, 9)]
    text = json.dumps({"camera_angle_x": 0.8, "frames": frames})
    (s / "transforms.json").write_text(text[: len(text) // 2])
    code, msg = cli_error(capsys, train_argv(s, tmp_path / "run"))
    assert code == 1
    assert str(s / "transforms.json") in msg and "corrupt or truncated JSON" in msg


def test_truncated_results_json_in_collect(trained_run, tmp_path, capsys):
    runs = tmp_path / "runs"
    shutil.copytree(trained_run, runs / "r1")
    p = runs / "r1" / "results.json"
    p.write_text(json.dumps({"run_id": "x", "metrics": {"psnr": 20.0}, "status": "done"})[:30])
    code, msg = cli_error(capsys, ["collect", str(runs)])
    assert code == 1
    assert str(p) in msg and "corrupt or truncated JSON" in msg


# ------------------------------------------------------------------------------------ checkpoints
def test_truncated_model_checkpoint_in_eval(trained_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(trained_run, run)
    p = run / "model.pt"
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    code, msg = cli_error(capsys, ["eval", str(run), "--no-progress"])
    assert code == 1
    assert str(p) in msg and "corrupt or truncated checkpoint" in msg


def test_truncated_training_checkpoint_on_resume(scene, trained_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(trained_run, run)
    p = run / "checkpoint.pt"
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 3])
    st = json.loads((run / "status.json").read_text())
    st["state"] = "running"                  # as if the process died: train resumes from the checkpoint
    (run / "status.json").write_text(json.dumps(st))
    code, msg = cli_error(capsys, train_argv(scene, run))
    assert code == 1
    assert str(p) in msg and "corrupt or truncated checkpoint" in msg


# ------------------------------------------------------------------------------------ classes / queries
def test_unknown_class_in_3dovs_segmentation(scene, tmp_path, capsys):
    s = copy_scene(scene, tmp_path)
    p = s / "segmentations" / "001" / "unicorn.png"
    shutil.copy(s / "segmentations" / "001" / "ball.png", p)
    code, msg = cli_error(capsys, train_argv(s, tmp_path / "run"))
    assert code == 1
    assert str(p) in msg and "'unicorn'" in msg and "classes.txt" in msg


def test_unknown_class_in_3dovs_predictions(scene, tmp_path, capsys):
    pred = tmp_path / "pred" / "001"
    pred.mkdir(parents=True)
    cv2.imwrite(str(pred / "unicorn.png"), np.zeros((24, 32), np.uint8))
    code, msg = cli_error(capsys, ["eval", "--masks", str(tmp_path / "pred"), "--layout", str(scene),
                                   "--protocol", "3dovs", "--out", str(tmp_path / "out")])
    assert code == 1
    assert str(pred / "unicorn.png") in msg and "unknown class 'unicorn'" in msg


def test_unknown_query_in_lerf_predictions(scene, tmp_path, capsys):
    pred = tmp_path / "pred" / "frame_00003"
    pred.mkdir(parents=True)
    cv2.imwrite(str(pred / "ball.png"), np.zeros((24, 32), np.uint8))      # a known query is fine
    cv2.imwrite(str(pred / "unicorn.png"), np.zeros((24, 32), np.uint8))
    code, msg = cli_error(capsys, ["eval", "--masks", str(tmp_path / "pred"), "--layout",
                                   str(scene / "label" / "tabletop-small"), "--protocol", "lerf",
                                   "--out", str(tmp_path / "out")])
    assert code == 1
    assert str(pred / "unicorn.png") in msg and "unknown query 'unicorn'" in msg
    assert not (tmp_path / "out" / "results.json").exists()


# ------------------------------------------------------------------------------------ grids
def test_grid_with_unknown_axis(tmp_path, capsys):
    g = tmp_path / "grid.yaml"
    g.write_text("study: depth_formulation\nbase:\n  method: gaussiands\n  preset: cpu-small\n"
                 "scenes: [tabletop-small]\nseeds: [0]\naxes:\n  gaussiands.depth_formulaton: [none, raw_l1]\n")
    code, msg = cli_error(capsys, ["ablate", "--grid", str(g), "--out", str(tmp_path / "runs"), "--dry-run"])
    assert code == 1
    assert str(g) in msg and "unknown config key 'gaussiands.depth_formulaton'" in msg


def test_corrupt_grid_yaml_is_one_line(tmp_path, capsys):
    g = tmp_path / "grid.yaml"
    g.write_text("study: depth_formulation\naxes: {gaussiands.depth_formulation: [none\n")
    code, msg = cli_error(capsys, ["ablate", "--grid", str(g), "--out", str(tmp_path / "runs")])
    assert code == 1
    assert str(g) in msg and "YAML" in msg


# ------------------------------------------------------------------------------------ output folders
def _blocked(tmp_path: Path) -> Path:
    """A folder below a regular file: not creatable, even by root (chmod does not stop root)."""
    f = tmp_path / "a_file.txt"
    f.write_text("x")
    return f / "sub"


def test_output_not_writable_train(scene, tmp_path, capsys):
    out = _blocked(tmp_path)
    code, msg = cli_error(capsys, train_argv(scene, out))
    assert code == 1
    assert str(tmp_path / "a_file.txt") in msg and "Not a directory" in msg


def test_output_not_writable_make_scene(tmp_path, capsys):
    out = _blocked(tmp_path)
    code, msg = cli_error(capsys, ["make-scene", "--preset", "tabletop-small", "--views", "8", "--resolution", "32x24",
                                   "--out", str(out), "--quiet"])
    assert code == 1
    assert str(tmp_path / "a_file.txt") in msg and "not a folder" in msg


def test_output_not_writable_stress(tmp_path, capsys):
    out = _blocked(tmp_path)
    code, msg = cli_error(capsys, ["stress", "--component", "loss:tv", "--out", str(out)])
    assert code == 1
    assert str(out) in msg and "Not a directory" in msg


def test_output_not_writable_ablate(tmp_path, capsys):
    out = _blocked(tmp_path)
    code, msg = cli_error(capsys, ["ablate", "--grid", "tiny-test", "--out", str(out), "--executor", "serial"])
    assert code == 1
    assert str(tmp_path / "a_file.txt") in msg and "Not a directory" in msg


def test_output_not_writable_mask_scoring(scene, tmp_path, capsys):
    out = _blocked(tmp_path)
    (tmp_path / "pred").mkdir()
    code, msg = cli_error(capsys, ["eval", "--masks", str(tmp_path / "pred"), "--layout",
                                   str(scene / "label" / "tabletop-small"), "--protocol", "lerf", "--out", str(out)])
    assert code == 1
    assert str(tmp_path / "a_file.txt") in msg and "Not a directory" in msg


def test_output_not_writable_report(trained_run, tmp_path, capsys):
    runs = tmp_path / "runs"
    shutil.copytree(trained_run, runs / "r1")
    assert main(["eval", str(runs / "r1"), "--no-progress"]) == 0
    capsys.readouterr()
    out = _blocked(tmp_path)
    code, msg = cli_error(capsys, ["report", str(runs), "--out", str(out), "--no-progress"])
    assert code == 1
    assert str(tmp_path / "a_file.txt") in msg and "Not a directory" in msg


# ------------------------------------------------------------------------------------ the real executable
def test_console_script_exit_code_and_single_line(scene, tmp_path):
    s = copy_scene(scene, tmp_path)
    (s / "images" / "frame_00006.png").unlink()
    exe = Path(sys.executable).parent / "gsbench"
    proc = subprocess.run([str(exe), *train_argv(s, tmp_path / "run")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert lines[-1].startswith("gsbench train: error: ") and str(s / "images" / "frame_00006.png") in lines[-1]
    assert "Traceback" not in proc.stderr
