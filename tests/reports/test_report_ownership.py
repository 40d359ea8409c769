"""The report folder is owned (gsbench.outdir): files the report did not write are refused or, with
--force, kept and never deleted; a killed or size-limited report leaves the old one as it was; of
two reports into one folder at once one wins whole and the other fails with one line."""
from __future__ import annotations

import os
import re
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from previews_fake import fake_previews
from report_runs import write_run

from gsbench.cli import main
from gsbench.outdir import MANIFEST

ME_JPG = b"\xff\xd8\xff\xe0 a holiday picture"
THESIS = "\\section{Results} my own words\n"

# `gsbench report` whose table step signals (first argv) and then waits until a gate file (second
# argv) exists: a report caught in the middle of writing its folder.
HELD = """
import sys, time
from pathlib import Path
from gsbench.reports import build
real = build._write_tables
def held(*a, **k):
    real(*a, **k)
    Path(sys.argv[1]).write_text("writing")
    while not Path(sys.argv[2]).exists():
        time.sleep(0.05)
build._write_tables = held
from gsbench.cli import main
sys.exit(main(sys.argv[3:]))
"""


@pytest.fixture
def runs(tmp_path: Path) -> Path:
    root = tmp_path / "runs"
    g = write_run(root, "gds", method="gaussiands", scene="bench", metrics={"psnr": 20.0, "miou_3dovs": 0.75})
    write_run(root, "van", method="vanilla", scene="bench", metrics={"psnr": 19.0})
    fake_previews(g, "gaussiands")
    return root


def _report(runs: Path, out: Path, *extra: str) -> list[str]:
    return ["report", str(runs), "--out", str(out), "--no-progress", *extra]


def _last_line(err: str) -> str:
    return [ln for ln in err.splitlines() if ln.strip()][-1]


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _users_files(out: Path) -> None:
    (out / "pictures" / "holiday").mkdir(parents=True)
    (out / "pictures" / "holiday" / "me.jpg").write_bytes(ME_JPG)
    (out / "tables").mkdir()
    (out / "tables" / "thesis.tex").write_text(THESIS)


def _assert_users_files(out: Path) -> None:
    assert (out / "pictures" / "holiday" / "me.jpg").read_bytes() == ME_JPG
    assert (out / "tables" / "thesis.tex").read_text() == THESIS


def _assert_whole(out: Path) -> None:
    """Every picture and plot index.html shows is there, and the manifest lists what the folder holds."""
    page = (out / "index.html").read_text()
    srcs = re.findall(r'<img src="([^"]+)"', page)
    assert len(srcs) >= 10 and all((out / s).is_file() for s in srcs)
    import json
    listed = set(json.loads((out / MANIFEST).read_text())["files"])
    held = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()} - {MANIFEST}
    assert set(srcs) <= listed and listed == held


def _leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if ".staging-" in p.name or p.name.endswith((".lock", ".takeover")))


def _start_held(runs: Path, out: Path, tmp_path: Path) -> tuple[subprocess.Popen, Path]:
    signal_file, gate = tmp_path / "writing", tmp_path / "gate"
    p = subprocess.Popen([sys.executable, "-c", HELD, str(signal_file), str(gate), *_report(runs, out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    while not signal_file.exists():
        assert p.poll() is None, p.communicate()
        assert time.time() < deadline, "the held report never reached its tables"
        time.sleep(0.05)
    return p, gate


# ------------------------------------------------------------------ foreign files
def test_a_folder_with_foreign_files_is_refused_and_they_are_kept(runs, tmp_path, capsys):
    out = tmp_path / "P"
    _users_files(out)
    assert main(_report(runs, out)) == 1
    line = _last_line(capsys.readouterr().err)
    assert line.startswith("gsbench report: error:") and "pictures/holiday/me.jpg" in line and "--force" in line
    _assert_users_files(out)
    assert sorted(os.listdir(out)) == ["pictures", "tables"] and _leftovers(tmp_path) == []


def test_force_keeps_foreign_files_and_a_rerun_replaces_only_its_own(runs, tmp_path, capsys):
    out = tmp_path / "P"
    _users_files(out)
    assert main(_report(runs, out, "--force")) == 0
    _assert_users_files(out)
    page = (out / "index.html").read_text()
    assert "me.jpg" not in (out / MANIFEST).read_text() and "thesis" not in page
    # a re-run with --force: the user's files are still kept, the report's own are replaced
    (runs / "van").rename(tmp_path / "van-gone")
    assert main(_report(runs, out, "--force")) == 0
    _assert_users_files(out)
    assert "vanilla" not in (out / "tables" / "reconstruction.md").read_text()
    assert _leftovers(tmp_path) == []
    # without --force the folder still holds files the report did not write
    capsys.readouterr()
    assert main(_report(runs, out)) == 1
    assert "pictures/holiday/me.jpg" in _last_line(capsys.readouterr().err)


def test_force_never_overwrites_a_users_file_where_the_report_writes_one(runs, tmp_path, capsys):
    out = tmp_path / "P"
    out.mkdir()
    (out / "index.html").write_text("<p>my page</p>")
    assert main(_report(runs, out, "--force")) == 1
    line = _last_line(capsys.readouterr().err)
    assert f"{out / 'index.html'}: not written by gsbench report" in line
    assert (out / "index.html").read_text() == "<p>my page</p>" and os.listdir(out) == ["index.html"]


def test_a_report_file_changed_by_hand_is_foreign(runs, tmp_path, capsys):
    out = tmp_path / "P"
    assert main(_report(runs, out)) == 0
    (out / "tables.md").write_text("# my edits\n")
    capsys.readouterr()
    assert main(_report(runs, out)) == 1
    assert "e.g. tables.md" in _last_line(capsys.readouterr().err)
    assert (out / "tables.md").read_text() == "# my edits\n"


def test_a_manifest_naming_paths_outside_the_folder_deletes_nothing_there(runs, tmp_path):
    out = tmp_path / "P"
    out.mkdir()
    (tmp_path / "victim.txt").write_text("keep me")
    (out / MANIFEST).write_text('{"command": "gsbench report", "files": {"../victim.txt": {"size": 7}}}')
    assert main(_report(runs, out)) == 0
    assert (tmp_path / "victim.txt").read_text() == "keep me"
    _assert_whole(out)


# ------------------------------------------------------------------ killed, size-limited, concurrent
@pytest.mark.slow   # a second process that imports the reports: ~8 s of CPU on 2 cores
def test_a_killed_report_leaves_the_old_report_intact(runs, tmp_path):
    out = tmp_path / "P"
    assert main(_report(runs, out)) == 0
    before = _snapshot(out)
    p, _ = _start_held(runs, out, tmp_path)
    p.send_signal(signal.SIGKILL)
    p.wait()
    assert _snapshot(out) == before
    assert any(".staging-" in n for n in _leftovers(tmp_path))        # what the kill left beside it
    assert main(_report(runs, out)) == 0                                # taken over and cleaned up
    assert _leftovers(tmp_path) == []
    _assert_whole(out)


def _limit_file_size() -> None:
    resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))


@pytest.mark.slow   # a second process that imports the reports: ~8 s of CPU on 2 cores
def test_a_size_limited_report_leaves_the_old_report_intact_and_names_the_file(runs, tmp_path):
    out = tmp_path / "P"
    assert main(_report(runs, out)) == 0
    before = _snapshot(out)
    assert max(len(v) for v in before.values()) > 4096                # the limit bites
    r = subprocess.run([sys.executable, "-m", "gsbench.cli", *_report(runs, out)], capture_output=True, text=True,
                       preexec_fn=_limit_file_size, timeout=120)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr[-2000:]
    line = _last_line(r.stderr)
    assert line.startswith("gsbench report: error:") and "File too large" in line
    named = line[len("gsbench report: error: "):].split(": File too large")[0]
    assert Path(named).name in {Path(k).name for k in before}, line     # a file of the report, by its path
    assert _snapshot(out) == before and _leftovers(tmp_path) == []


def test_the_atomic_writers_name_the_file_when_the_write_itself_fails(tmp_path):
    """EFBIG (and ENOSPC, EIO) come from write() with no file name: the writer attaches its path."""
    code = ("import sys\nfrom gsbench.store import write_bytes_atomic\n"
            "try:\n    write_bytes_atomic(sys.argv[1], b'x' * 100000)\n"
            "except OSError as e:\n    print(e.errno, e.filename)\n")
    target = tmp_path / "big.bin"
    r = subprocess.run([sys.executable, "-c", code, str(target)], capture_output=True, text=True,
                       preexec_fn=_limit_file_size, timeout=60)
    assert r.stdout.split() == ["27", str(target)], r.stderr
    assert os.listdir(tmp_path) == []                                   # no temporary file left


@pytest.mark.slow   # a second process that imports the reports: ~8 s of CPU on 2 cores
def test_two_reports_into_one_folder_one_wins_whole_the_other_fails(runs, tmp_path, capsys):
    out = tmp_path / "P"
    first, gate = _start_held(runs, out, tmp_path)
    try:
        assert main(_report(runs, out)) == 1
        line = _last_line(capsys.readouterr().err)
        assert line.startswith("gsbench report: error:") and "another process is writing this report folder" in line
        assert f"pid {first.pid}" in line
    finally:
        gate.write_text("go")
        _, err = first.communicate(timeout=120)
    assert first.returncode == 0, err[-2000:]
    _assert_whole(out)
    assert _leftovers(tmp_path) == []
