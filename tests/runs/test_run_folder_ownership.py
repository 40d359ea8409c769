"""`gsbench train --out` writes only a run's own folder (gsbench.outdir.check_run_folder): never a
folder of a user's files, the root, the scene, gsbench's project tree or the published store; a run
folder to resume passes, with what a killed writer leaves in it. The hostile:output battery's train,
link-loop, root, long-path, file-mode and SIGTERM cases run here through the real CLI."""
from __future__ import annotations

import json
import shutil

import pytest

from gsbench.commands.hostile import run_hostile
from gsbench.commands.hostile.output import CASES
from gsbench.errors import InputError
from gsbench.outdir import check_run_folder, first_foreign_in_run

NEW = ("train", "symbolic link loop", "report --out /", "10,000-character", "normal mode", "SIGTERM")
RUN_CASES = [c for c in CASES if any(w in c.name for w in NEW)]


@pytest.mark.parametrize("case", RUN_CASES, ids=[c.name for c in RUN_CASES])
def test_hostile_output_run_folder_case(case):
    r = run_hostile(case)
    assert r.passed, r.note


def test_the_battery_has_the_run_folder_cases():
    names = " | ".join(c.name for c in RUN_CASES)
    for words in ("env.json and model.pt", "train --out /", "the scene folder", "project tree", "published store",
                  "report --out a symbolic link loop", "stress --out a symbolic link loop", "SIGTERM"):
        assert words in names


def test_a_run_folder_to_resume_passes(tiny_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    (run / ".model.pt.x1y2.tmp").write_bytes(b"half")          # an atomic write cut short
    (run / "previews").mkdir()
    (run / "writer.lock").write_text("{}")
    assert first_foreign_in_run(run) is None
    check_run_folder(run)
    check_run_folder(tmp_path / "new")                         # a new folder
    (tmp_path / "empty").mkdir()
    check_run_folder(tmp_path / "empty")


def test_without_a_runs_config_nothing_but_the_lock_is_a_runs(tmp_path):
    out = tmp_path / "R"
    out.mkdir()
    (out / "writer.lock").write_text("{}")
    assert first_foreign_in_run(out) is None
    (out / "status.json").write_text('{"state": "done"}')
    assert first_foreign_in_run(out) == "status.json"
    (out / "config.json").write_text(json.dumps({"method": "vanilla"}))     # not a run's: no run_id, no scene
    with pytest.raises(InputError, match=r"R: holds files that are not a gsbench run's, e.g. config.json"):
        check_run_folder(out)


def test_a_runs_folder_with_a_foreign_subfolder_is_refused(tiny_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    (run / "photos").mkdir()
    assert first_foreign_in_run(run) == "photos"


def test_inside_a_store_or_a_scene_is_refused(tiny_scene, tmp_path):
    (tmp_path / "store" / "_shared").mkdir(parents=True)
    with pytest.raises(InputError, match="published results store"):
        check_run_folder(tmp_path / "store" / "grid" / "run")
    with pytest.raises(InputError, match="scene folder"):
        check_run_folder(tiny_scene / "sparse", tiny_scene)
