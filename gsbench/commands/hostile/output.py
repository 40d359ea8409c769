"""Hostile inputs: folders a command writes: report, make-scene, stress, claims, ablate, points.

A folder that holds someone else's files is refused, or with --force written beside them; nothing
a command did not write is ever deleted or overwritten; a second writer into a folder fails with one
line naming the first (the battery: gsbench/commands/hostile/__init__.py; the rule: gsbench/outdir.py).
"""
from __future__ import annotations

import contextlib
import functools
import io
import json
import os
import socket
import time
from pathlib import Path
from typing import Callable, Optional

from gsbench.cli import main
from gsbench.commands.hostile import Hostile, _base_dir, tiny_run
from gsbench.grids.claims_plan import CLAIM_GRIDS

ME_JPG = b"\xff\xd8\xff\xe0 a holiday picture"
THESIS = "\\section{Results} my own words\n"


@functools.lru_cache(maxsize=None)
def _evaluated_runs() -> Path:
    """A runs folder with one finished, evaluated tiny run: what `gsbench report` reads (read only)."""
    runs = _base_dir() / "output_runs"
    run = tiny_run(runs / "r1")
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        if main(["eval", str(run), "--no-progress", "--quiet"]) != 0:
            raise RuntimeError("hostile battery: could not evaluate the tiny run")
    return runs


def _report(out: Path, *extra: str) -> list[str]:
    return ["report", str(_evaluated_runs()), "--out", str(out), "--no-progress", *extra]


def _users_files(out: Path) -> None:
    (out / "pictures" / "holiday").mkdir(parents=True)
    (out / "pictures" / "holiday" / "me.jpg").write_bytes(ME_JPG)
    (out / "tables").mkdir()
    (out / "tables" / "thesis.tex").write_text(THESIS)


def _users_files_kept(out: Path) -> Optional[str]:
    for rel, want in (("pictures/holiday/me.jpg", ME_JPG), ("tables/thesis.tex", THESIS.encode())):
        p = out / rel
        if not p.is_file() or p.read_bytes() != want:
            return f"{rel} was deleted or changed"
    return None


def _no_litter(folder: Path) -> Optional[str]:
    """Nothing a writer leaves behind: staging folders, lock files, takeover guards."""
    left = sorted(p.name for p in folder.rglob("*") if ".staging-" in p.name or p.name.endswith(".takeover"))
    return f"left behind: {left}" if left else None


def _checks(*fns: Callable[[Path, int, str], Optional[str]]) -> Callable[[Path, int, str], Optional[str]]:
    def check(folder: Path, code: int, err: str) -> Optional[str]:
        return next((why for fn in fns if (why := fn(folder, code, err))), None)
    return check


def _live_lock(path: Path, command: str) -> None:
    """A lock record of a live writer on this host: pid 1 is alive everywhere and is not us."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"pid": 1, "host": socket.gethostname(), "started": time.time(),
                                "command": command, "token": "other"}))


# ------------------------------------------------------------------ report
def _report_foreign(folder: Path) -> list[str]:
    _users_files(folder / "P")
    return _report(folder / "P")


def _report_force(folder: Path) -> list[str]:
    _users_files(folder / "P")
    return _report(folder / "P", "--force")


def _report_force_clash(folder: Path) -> list[str]:
    (folder / "P").mkdir()
    (folder / "P" / "index.html").write_text("<p>my own page</p>")
    return _report(folder / "P", "--force")


def _report_changed(folder: Path) -> list[str]:
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        if main(_report(folder / "P", "--quiet")) != 0:
            raise RuntimeError("could not write the first report")
    (folder / "P" / "tables.md").write_text("# edited by hand\n")
    return _report(folder / "P")


def _report_manifest_outside(folder: Path) -> list[str]:
    (folder / "victim.txt").write_text("keep me")
    (folder / "P").mkdir()
    listed = {"../victim.txt": {"size": 7, "sha256": "0" * 64}, "/etc/hostname": {"size": 1, "sha256": "0" * 64}}
    (folder / "P" / ".gsbench-manifest.json").write_text(json.dumps({"command": "gsbench report", "files": listed}))
    return _report(folder / "P")


def _report_locked(folder: Path) -> list[str]:
    _live_lock(folder / ".P.writer.lock", "gsbench report (the other one)")
    return _report(folder / "P")


# ------------------------------------------------------------------ runs folders, other commands
def _ablate_loser(folder: Path) -> list[str]:
    _live_lock(folder / "runs" / "writer.lock", "gsbench ablate --grid tiny-test (the winner)")
    return ["ablate", "--grid", "tiny-test", "--out", str(folder / "runs"), "--executor", "serial", "--no-progress"]


def _ablate_foreign(folder: Path) -> list[str]:
    (folder / "runs").mkdir()
    (folder / "runs" / "notes.txt").write_text("my notes")
    return ["ablate", "--grid", "tiny-test", "--out", str(folder / "runs"), "--executor", "serial", "--no-progress"]


def _claims_foreign(folder: Path) -> list[str]:
    (folder / "runs").mkdir()
    (folder / "runs" / "notes.txt").write_text("my notes")
    return ["claims", "--quick", "--grids", CLAIM_GRIDS[0], "--out", str(folder / "runs"), "--executor", "serial",
            "--no-progress"]


def _stress_foreign(folder: Path) -> list[str]:
    (folder / "out").mkdir()
    (folder / "out" / "results.csv").write_text("mine\n")
    return ["stress", "--component", "hostile:none", "--out", str(folder / "out")]


def _make_scene_nonempty(folder: Path) -> list[str]:
    (folder / "out").mkdir()
    (folder / "out" / "me.jpg").write_bytes(ME_JPG)
    return ["make-scene", "--preset", "tabletop-small", "--views", "8", "--resolution", "32x24", "--out",
            str(folder / "out"), "--no-progress"]


def _points_foreign(folder: Path) -> list[str]:
    """A scene at 96x72 (the tiny one's 32x24 has too few keypoints to triangulate) with a user's file
    in sparse/0, whose points `points --force` replaces."""
    scene = folder / "scene"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        if main(["make-scene", "--preset", "tabletop-small", "--views", "8", "--resolution", "96x72", "--out",
                 str(scene), "--no-progress", "--quiet"]) != 0:
            raise RuntimeError("could not make the scene")
    (scene / "sparse" / "0" / "notes.txt").write_text("my notes")
    return ["points", str(scene), "--force"]


def _kept(rel: str, want: str | bytes) -> Callable[[Path, int, str], Optional[str]]:
    def check(folder: Path, code: int, err: str) -> Optional[str]:
        p = folder / rel
        data = want.encode() if isinstance(want, str) else want
        return None if p.is_file() and p.read_bytes() == data else f"{rel} was deleted or changed"
    return check


def _only(rel: str, names: set[str]) -> Callable[[Path, int, str], Optional[str]]:
    def check(folder: Path, code: int, err: str) -> Optional[str]:
        got = set(os.listdir(folder / rel)) if (folder / rel).is_dir() else set()
        return None if got == names else f"{rel} holds {sorted(got)}, expected {sorted(names)}"
    return check


def _report_whole(folder: Path, code: int, err: str) -> Optional[str]:
    return None if (folder / "P" / "index.html").is_file() else "no index.html"


CASES: list[Hostile] = [
    Hostile("output", "report into a folder of someone else's files", _report_foreign,
            ("pictures/holiday/me.jpg", "did not write", "--force"),
            check=_checks(lambda f, c, e: _users_files_kept(f / "P"), _only("P", {"pictures", "tables"}),
                          lambda f, c, e: _no_litter(f))),
    Hostile("output", "report --force keeps someone else's files", _report_force, exit_code=0,
            check=_checks(lambda f, c, e: _users_files_kept(f / "P"), _report_whole, lambda f, c, e: _no_litter(f))),
    Hostile("output", "report --force where a user's file has a report file's name", _report_force_clash,
            ("index.html", "never overwrites"),
            check=_checks(_kept("P/index.html", "<p>my own page</p>"), lambda f, c, e: _no_litter(f))),
    Hostile("output", "report over its own folder with a file edited by hand", _report_changed,
            ("tables.md", "did not write (or that changed since)"),
            check=_kept("P/tables.md", "# edited by hand\n")),
    Hostile("output", "report folder whose manifest lists files outside it", _report_manifest_outside, exit_code=0,
            check=_checks(_kept("victim.txt", "keep me"), _report_whole)),
    Hostile("output", "report into a folder another report is writing", _report_locked,
            ("another process is writing this report folder", "pid 1"),
            check=_checks(_only(".", {".P.writer.lock"}), lambda f, c, e: _no_litter(f))),
    Hostile("output", "ablate loser: another ablate holds the runs folder", _ablate_loser,
            ("runs: another process is writing this runs folder", "pid 1", "the winner"),
            check=_only("runs", {"writer.lock"})),
    Hostile("output", "ablate into a folder of someone else's files", _ablate_foreign, ("notes.txt", "did not write"),
            check=_checks(_kept("runs/notes.txt", "my notes"), _only("runs", {"notes.txt"}))),
    Hostile("output", "claims into a folder of someone else's files", _claims_foreign, ("notes.txt", "did not write"),
            check=_checks(_kept("runs/notes.txt", "my notes"), _only("runs", {"notes.txt"}))),
    Hostile("output", "stress --out a folder of someone else's files", _stress_foreign,
            ("results.csv", "did not write"),
            check=_checks(_kept("out/results.csv", "mine\n"), _only("out", {"results.csv"}))),
    Hostile("output", "make-scene into a folder that is not empty", _make_scene_nonempty, ("not an empty folder",),
            check=_checks(_kept("out/me.jpg", ME_JPG), _only("out", {"me.jpg"}))),
    Hostile("output", "points --force keeps other files in sparse/0", _points_foreign, exit_code=0,
            check=_checks(_kept("scene/sparse/0/notes.txt", "my notes"),
                          lambda f, c, e: None if (f / "scene/sparse/points_provenance.json").is_file()
                          else "no points written")),
]
