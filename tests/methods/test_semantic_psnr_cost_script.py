"""benchmarks/semantic_psnr_cost.py: the paired t interval (and its guard below two seeds), the table it
prints, and that `--set` reaches GaussianDS only; the training itself is stubbed."""
from __future__ import annotations

import json
import math

import pytest
from bench_scripts import load_benchmark

T_975_DF2 = 4.302652729911275     # Student's t, 97.5 % quantile, 2 degrees of freedom (printed tables)


def test_the_paired_interval_is_students_t_on_the_differences_and_needs_two():
    mod = load_benchmark("semantic_psnr_cost")
    mean, low, high = mod.paired_interval([1.0, 2.0, 3.0])      # mean 2, sample sd 1
    assert mean == pytest.approx(2.0)
    assert high - mean == pytest.approx(T_975_DF2 / math.sqrt(3)) and mean - low == pytest.approx(high - mean)
    assert mod.paired_interval([-1.5]) == (-1.5, None, None)
    with pytest.raises(ValueError):
        mod.paired_interval([])


def test_main_prints_the_difference_and_passes_set_to_gaussiands_only(tmp_path, monkeypatch, capsys):
    mod = load_benchmark("semantic_psnr_cost")
    calls = []
    psnr = {("vanilla", 0): 27.0, ("vanilla", 1): 27.5, ("gaussiands", 0): 25.0, ("gaussiands", 1): 26.0}

    def fake(method, scene, preset, seed, sets, work):
        calls.append((method, seed, tuple(sets)))
        return {"psnr": psnr[(method, seed)], "ssim": 0.9, "miou_3dovs": 0.5 if method == "gaussiands" else None}

    monkeypatch.setattr(mod, "train_and_eval", fake)
    scene = tmp_path / "scene"
    scene.mkdir()
    out_json = tmp_path / "r.json"
    assert mod.main(["--scene", str(scene), "--seeds", "0", "1", "--set", "gaussiands.sem_geometry=detached",
                     "--work", str(tmp_path / "w"), "--json", str(out_json)]) == 0
    out = capsys.readouterr().out
    assert ("vanilla", 0, ()) in calls and ("gaussiands", 1, ("gaussiands.sem_geometry=detached",)) in calls
    assert "| 0 | 27.00 | 25.00 | -2.00 |" in out and "| 1 | 27.50 | 26.00 | -1.50 |" in out
    assert "GaussianDS - vanilla PSNR: -1.75 dB, 95 % t interval" in out and "n = 2 seeds" in out
    assert json.loads(out_json.read_text())["gaussiands_set"] == ["gaussiands.sem_geometry=detached"]
    capsys.readouterr()
    assert mod.main(["--scene", str(scene), "--seeds", "0", "--work", str(tmp_path / "w")]) == 0
    assert "no interval (n < 2)" in capsys.readouterr().out


def test_a_missing_scene_is_one_line(tmp_path):
    mod = load_benchmark("semantic_psnr_cost")
    with pytest.raises(SystemExit, match="not a folder"):
        mod.main(["--scene", str(tmp_path / "nope"), "--work", str(tmp_path / "w")])
