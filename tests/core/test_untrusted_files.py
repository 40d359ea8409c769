"""Files from elsewhere are data, not code, and one bad file never hides the rest.

A run folder may be downloaded: its model.pt / checkpoint.pt must not run code when loaded. A
truncated results.json among many runs is one failed row, not an error for all. A prediction folder of
another aspect ratio, or a scene folder given for a label folder, is refused on one line naming it.
"""
from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from gsbench.cli import main
from gsbench.errors import InputError
from gsbench.store import load_torch, save_torch_atomic


class _Payload:
    """Unpickling this object calls open(marker, "w"): the file appears only if the pickle ran code."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (open, (str(self.marker), "w"))


def _evil_file(path: Path, marker: Path) -> None:
    torch.save({"method": "vanilla", "field": _Payload(marker), "step": 3}, path)


def _one_error_line(capsys, argv: list[str]) -> str:
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith(f"gsbench {argv[0]}: error: ")]
    assert len(errors) == 1 and lines[-1] == errors[0], err
    return errors[0]


def test_the_payload_is_live_when_loaded_as_a_full_pickle(tmp_path):
    """Control: the crafted file does run code under a full unpickle, so the tests below can fail."""
    marker = tmp_path / "ran"
    _evil_file(tmp_path / "model.pt", marker)
    torch.load(tmp_path / "model.pt", weights_only=False)
    assert marker.exists()


def test_pickle_payload_in_model_pt_is_refused_by_eval(tiny_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    marker = tmp_path / "ran"
    _evil_file(run / "model.pt", marker)
    with pytest.raises(InputError, match=r"model.pt: refused: holds Python objects other than tensors"):
        load_torch(run / "model.pt")
    msg = _one_error_line(capsys, ["eval", str(run), "--no-progress"])
    # the file and the object (pickle names io.open `_io.open` from Python 3.12)
    assert str(run / "model.pt") in msg and re.search(r"it would call or build _?io\.open", msg)
    assert not marker.exists()


def test_pickle_payload_in_checkpoint_is_refused_on_resume(tiny_scene, tiny_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    marker = tmp_path / "ran"
    _evil_file(run / "checkpoint.pt", marker)
    st = json.loads((run / "status.json").read_text())
    st["state"] = "running"                      # as if the process died: train resumes from the checkpoint
    (run / "status.json").write_text(json.dumps(st))
    msg = _one_error_line(capsys, ["train", "--method", "vanilla", "--scene", str(tiny_scene), "--out", str(run),
                                   "--preset", "cpu-small", "--set", "train.iterations=2", "--set",
                                   "train.eval_every=0", "--no-progress"])
    assert str(run / "checkpoint.pt") in msg and "refused" in msg
    assert not marker.exists()


def test_every_file_a_run_writes_loads_as_data(tiny_run):
    for name in ("model.pt", "checkpoint.pt"):
        st = load_torch(tiny_run / name)
        assert isinstance(st, dict) and st


def test_saving_anything_but_tensors_and_plain_values_is_refused(tmp_path):
    with pytest.raises(TypeError, match=r"/info/when is a numpy.float64"):
        save_torch_atomic(tmp_path / "m.pt", {"field": {"x": torch.zeros(2)}, "info": {"when": np.float64(1.0)}})
    assert not (tmp_path / "m.pt").exists()
    save_torch_atomic(tmp_path / "m.pt", {"t": torch.ones(2), "l": [1, 2.5, "a", None, (True,)]})
    assert load_torch(tmp_path / "m.pt")["l"] == [1, 2.5, "a", None, (True,)]


# ------------------------------------------------------------------------------ collect / report
def _runs(tiny_run: Path, root: Path, n: int = 3) -> list[Path]:
    """n evaluated copies of the session's run, each with its own run_id."""
    base = root.parent / "evaluated"
    shutil.copytree(tiny_run, base)
    assert main(["eval", str(base), "--no-progress"]) == 0
    out = []
    for k in range(n):
        d = root / f"r{k}"
        shutil.copytree(base, d)
        res = json.loads((d / "results.json").read_text())
        res["run_id"] = f"run-{k}"
        (d / "results.json").write_text(json.dumps(res))
        out.append(d)
    return out


def test_one_truncated_results_json_among_many_runs(tiny_run, tmp_path, capsys):
    from gsbench.collect import read_collected
    runs = _runs(tiny_run, tmp_path / "runs")
    bad = runs[1] / "results.json"
    bad.write_text(bad.read_text()[:150])
    capsys.readouterr()
    assert main(["collect", str(tmp_path / "runs")]) == 0
    err = capsys.readouterr().err
    assert f"could not read {bad}: corrupt or truncated JSON" in err
    assert "could not read 1 results.json file(s)" in err
    df = read_collected(tmp_path / "runs" / "collected.parquet")
    assert df["run_dir"].nunique() == 3
    failed = df[df["run_dir"] == str(runs[1])]
    assert len(failed) == 1 and failed.iloc[0]["status"] == "failed"
    assert str(bad) in failed.iloc[0]["reason"] and failed.iloc[0]["method"] == "vanilla"   # from config.json
    good = df[(df["metric"] == "psnr") & (df["status"] == "done")]
    assert sorted(good["run_id"]) == ["run-0", "run-2"] and good["value"].notna().all()

    assert main(["report", str(tmp_path / "runs"), "--out", str(tmp_path / "rep"), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "could not read 1 results.json file(s)" in err
    html = (tmp_path / "rep" / "index.html").read_text()
    assert "Could not read 1 results.json file(s)" in html and "n/a (run failed)" in html


# ------------------------------------------------------------------------------ eval --masks
def _lerf_preds(label_dir: Path, out: Path, w: int, h: int) -> None:
    for lf in sorted(label_dir.glob("frame_*.json")):
        cats = {o["category"] for o in json.loads(lf.read_text())["objects"]}
        for q in cats:
            (out / lf.stem).mkdir(parents=True, exist_ok=True)
            assert cv2.imwrite(str(out / lf.stem / f"{q.replace('/', '_')}.png"), np.zeros((h, w), np.uint8))


def test_lerf_predictions_of_another_aspect_ratio_are_refused(tiny_scene, tmp_path, capsys):
    label_dir = tiny_scene / "label" / "tabletop-small"                      # 32x24 labels
    _lerf_preds(label_dir, tmp_path / "half", 16, 12)                         # same aspect ratio: scored
    assert main(["eval", "--masks", str(tmp_path / "half"), "--layout", str(label_dir), "--protocol", "lerf"]) == 0
    capsys.readouterr()
    _lerf_preds(label_dir, tmp_path / "wide", 17, 8)                          # 17x8 for 32x24: refused
    msg = _one_error_line(capsys, ["eval", "--masks", str(tmp_path / "wide"), "--layout", str(label_dir),
                                   "--protocol", "lerf"])
    assert str(tmp_path / "wide" / "frame_00001") in msg
    assert "prediction size 17x8 has another aspect ratio than the label file frame_00001.json (32x24)" in msg


def test_3dovs_predictions_of_another_aspect_ratio_are_refused(tiny_scene, tmp_path, capsys):
    seg = tiny_scene / "segmentations"
    view = sorted(d.name for d in seg.iterdir() if d.is_dir())[0]
    pred = tmp_path / "pred"
    pred.mkdir()
    assert cv2.imwrite(str(pred / f"{view}.png"), np.full((16, 30), 255, np.uint8))    # 30x16 for 32x24 views
    msg = _one_error_line(capsys, ["eval", "--masks", str(pred), "--layout", str(tiny_scene), "--protocol", "3dovs"])
    assert str(pred / f"{view}.png") in msg and "prediction size 30x16 has another aspect ratio" in msg
    assert f"GT masks of view {view} (32x24)" in msg


def test_scene_folder_given_for_the_label_folder(tiny_scene, tmp_path, capsys):
    (tmp_path / "pred").mkdir()
    msg = _one_error_line(capsys, ["eval", "--masks", str(tmp_path / "pred"), "--layout", str(tiny_scene),
                                   "--protocol", "lerf"])
    assert f"{tiny_scene}: holds no frame_*.json label files" in msg
    assert str(tiny_scene / "label" / "tabletop-small") in msg              # where they are
    assert "gsbench_scene.json" not in msg


# ------------------------------------------------------------------------------ train
def test_vanilla_train_prints_what_was_dropped_on_one_line(tiny_scene, tmp_path, capsys):
    assert main(["train", "--method", "vanilla", "--scene", str(tiny_scene), "--out", str(tmp_path / "v"),
                 "--preset", "cpu-small", "--set", "train.iterations=1", "--set", "train.eval_every=0",
                 "--no-progress"]) == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "dropped" in ln]
    assert len(lines) == 1, lines
    line = lines[0]
    assert line.count("gsbench") == 1 and line.startswith("gsbench: dropped (not used by this run): ")
    assert line.count("method vanilla is RGB only") == 1
    for part in ("priors.depth", "priors.masks", "priors.features", "semantic_channels"):
        assert part in line
    assert "semantic (method vanilla does not read it)" in line
