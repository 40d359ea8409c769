"""scripts/cpu_fingerprint.py: per-stage hashes of the golden runs, and the table that says which stage
moves between two files (CPUs or pinnings)."""
from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

import pytest
from paths import REPO_ROOT

SCRIPT = REPO_ROOT / "scripts" / "cpu_fingerprint.py"


def _module():
    spec = importlib.util.spec_from_file_location("cpu_fingerprint", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _file(path, stages):
    path.write_text(json.dumps({"cpu": {}, "env": {}, "stages": stages}))
    return path


def test_compare_names_the_first_differing_stage_of_each_group(tmp_path, capsys):
    fp = _module()
    base = {"probe/torch.linear": "a", "probe/numpy.f32": "b", "scene/images/0.png": "c",
            "vanilla/main/init": "d", "vanilla/main/s001/render": "e", "vanilla/main/s001/grad": "f",
            "vanilla/main/s002/render": "g", "vanilla/main/s002/loss": "h"}
    moved = {**base, "probe/torch.linear": "x", "vanilla/main/s002/loss": "y"}
    a, b = _file(tmp_path / "intel.json", base), _file(tmp_path / "amd.json", moved)
    c = _file(tmp_path / "same.json", base)
    assert fp.compare([a, b, c]) == 1
    rows = {ln.split(" | ")[0].strip("| "): ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("| ")}
    assert rows["probe/torch.linear"].endswith("| differs | same |")
    assert rows["probe/numpy.f32"].endswith("| same | same |")
    assert rows["scene"].endswith("| same | same |")
    assert rows["vanilla/main"].endswith("| differs from s002/loss | same |")
    assert fp.compare([a, c]) == 0


def test_hashes_see_one_ulp_and_the_dtype():
    fp = _module()
    import numpy as np
    x = np.linspace(0, 1, 100, dtype=np.float32)
    y = x.copy()
    y[50] = np.nextafter(y[50], np.float32(2))
    assert fp.digest(x) == fp.digest(x.copy()) != fp.digest(y)
    assert fp.digest(x) != fp.digest(x.astype(np.float64))


@pytest.mark.slow
def test_write_records_probes_scene_and_each_steps_stages(tmp_path):
    out = tmp_path / "fp.json"
    proc = subprocess.run([sys.executable, str(SCRIPT), "write", str(out), "--steps", "2", "--methods", "vanilla"],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    stages = json.loads(out.read_text())["stages"]
    for key in ("probe/torch.linear", "probe/numba.exp_f32", "vanilla/main/init", "vanilla/main/s001/render",
                "vanilla/main/s001/loss", "vanilla/main/s001/grad", "vanilla/main/s001/adam",
                "vanilla/main/s002/field"):
        assert key in stages
    assert any(k.startswith("scene/") for k in stages)
