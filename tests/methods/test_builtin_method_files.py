"""A new built-in method is two files beside the others (the method and its spec), and nothing else is
edited: the method table discovers the spec, the config takes the spec's section with its defaults and
rules, and the method trains and evaluates. The two files go into a temporary folder that a fresh
process appends to gsbench.methods' search path, so the repository's methods/ is never written to."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

METHOD = '''
"""`halfssim`: vanilla 3DGS whose D-SSIM weight is its own setting."""
from gsbench.methods.vanilla import Vanilla


class HalfSsim(Vanilla):
    name = "halfssim"
'''

SPEC = '''
"""The spec of `halfssim`: its own section (defaults and a rule) and vanilla's rules otherwise."""
from gsbench.config_keys import unit
from gsbench.method_table import MethodSpec
from gsbench.methods import vanilla_spec


def resolve(cfg, scene, drop):
    vanilla_spec.resolve(cfg, scene, drop)
    cfg["train"]["lambda_dssim"] = float(cfg["halfssim"]["dssim"])


SPEC = MethodSpec(name="halfssim", target="gsbench.methods.halfssim:HalfSsim", label="Half SSIM",
                  section="halfssim", resolve=f"{__name__}:resolve", uses="gsbench.methods.vanilla_spec:uses",
                  budget="gsbench.methods.vanilla_spec:budget", defaults={"dssim": 0.5},
                  rules={"halfssim.dssim": unit()}, order=5)
'''

DRIVER = '''
import sys
import gsbench.methods
gsbench.methods.__path__.append(sys.argv[1])        # the two new files, as if they sat in methods/
from gsbench.cli import main
raise SystemExit(main(sys.argv[2:]))
'''


def _run(folder: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", DRIVER, str(folder), *args], capture_output=True, text=True,
                          timeout=600)


def _two_files(tmp_path: Path) -> Path:
    folder = tmp_path / "new_method"
    folder.mkdir()
    (folder / "halfssim.py").write_text(textwrap.dedent(METHOD))
    (folder / "halfssim_spec.py").write_text(textwrap.dedent(SPEC))
    return folder


def test_a_new_builtin_method_is_two_files(tmp_path, tiny_scene):
    folder = _two_files(tmp_path)
    listed = _run(folder, "train", "--help")
    assert listed.returncode == 0 and "halfssim" in listed.stdout

    bad = _run(folder, "train", "--method", "halfssim", "--scene", str(tiny_scene), "--out", str(tmp_path / "x"),
               "--set", "halfssim.dssim=2")
    assert bad.returncode != 0 and "halfssim.dssim" in bad.stderr and "in [0, 1]" in bad.stderr  # its own rule

    run = tmp_path / "run"
    args = ["--preset", "cpu-small", "--set", "train.iterations=2", "train.eval_every=0", "train.checkpoint_every=0"]
    done = _run(folder, "train", "--method", "halfssim", "--scene", str(tiny_scene), "--out", str(run),
                "--no-progress", *args)
    assert done.returncode == 0, done.stderr[-3000:]
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["halfssim"] == {"dssim": 0.5} and cfg["train"]["lambda_dssim"] == 0.5   # defaults; resolver ran
    assert "semantic" in cfg["dropped"]       # a shared section it does not read, and says so
    evaluated = _run(folder, "eval", str(run), "--no-progress")
    assert evaluated.returncode == 0, evaluated.stderr[-3000:]
    res = json.loads((run / "results.json").read_text())
    assert res["method"] == "halfssim" and res["metrics"]["psnr"] is not None


def test_the_repository_is_untouched_by_it():
    """The discovered built-ins are exactly the method files of methods/ (the test above wrote none there)."""
    from gsbench.method_table import builtin_spec_modules
    root = Path(__file__).resolve().parents[2] / "methods"
    on_disk = sorted([f"gsbench.methods.{p.stem}" for p in root.glob("*_spec.py")]
                     + [f"gsbench.methods.{p.parent.name}.spec" for p in root.glob("*/spec.py")])
    assert builtin_spec_modules() == on_disk and "gsbench.methods.halfssim_spec" not in on_disk
