"""Hostile inputs: folders a command writes: report, make-scene, stress, claims, ablate, points, train.

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
import signal
import socket
import stat
import threading
import time
from pathlib import Path
from typing import Callable, Optional

import gsbench
from gsbench.cli import main
from gsbench.commands.hostile import Hostile, _base_dir, tiny_run, tiny_scene
from gsbench.grids.claims_plan import CLAIM_GRIDS
from gsbench.outdir import project_root

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


# ------------------------------------------------------------------ train --out: run folders
TRAIN = ["--method", "vanilla", "--preset", "cpu-small", "--set", "train.iterations=2", "--set", "train.eval_every=0",
         "--no-progress", "--quiet"]
# the arguments the battery's tiny run was trained with (gsbench.commands.hostile._tiny_run): its run id
TINY_RUN_ARGS = [*TRAIN, "--set", "priors.masks.provider=gt", "--set", "semantic.autoencoder.epochs=2"]
MODEL_PT = b"my own model"


def _train(folder: Path, out: Path | str, *extra: str) -> list[str]:
    return ["train", "--scene", str(tiny_scene(folder / "scene")), "--out", str(out), *TRAIN, *extra]


def _train_users_files(folder: Path) -> list[str]:
    (folder / "R").mkdir()
    (folder / "R" / "env.json").write_text('{"mine": true}')
    (folder / "R" / "model.pt").write_bytes(MODEL_PT)
    return _train(folder, folder / "R")


def _train_into_scene(folder: Path) -> list[str]:
    scene = tiny_scene(folder / "scene")
    return ["train", "--scene", str(scene), "--out", str(scene), *TRAIN]


def _train_inside_scene(folder: Path) -> list[str]:
    scene = tiny_scene(folder / "scene")
    return ["train", "--scene", str(scene), "--out", str(scene / "images" / "run"), *TRAIN]


def _train_into_project(folder: Path) -> list[str]:
    root = project_root() or Path(gsbench.__file__).resolve().parent
    return _train(folder, root)


def _train_into_store(folder: Path) -> list[str]:
    """A copy of a published store's layout: _shared/ parts and a grid folder of cells."""
    store = folder / "store"
    (store / "_shared").mkdir(parents=True)
    (store / "_shared" / "0123456789abcdef.json").write_text("{}\n")
    (store / "lambda_grid-cpu").mkdir()
    (store / "lambda_grid-cpu" / "02f0628ea601f44d.json").write_text('{"store_version": 2}\n')
    return _train(folder, store / "lambda_grid-cpu" / "mine")


def _loop(folder: Path) -> Path:
    (folder / "loop").symlink_to("loop")
    return folder / "loop"


def _train_resume(folder: Path) -> list[str]:
    """The battery's tiny run, left as an interrupted run: status "interrupted", a stale lock (a
    process that is gone), an atomic write's leftover temporary file. Training resumes it."""
    run = tiny_run(folder / "run")
    (run / "status.json").write_text(json.dumps({"state": "interrupted", "message": "terminated (SIGTERM)"}))
    (run / "writer.lock").write_text(json.dumps({"pid": 2 ** 22 + 1, "host": socket.gethostname(),
                                                 "started": time.time(), "command": "gone", "token": "x"}))
    (run / ".config.json.abc123.tmp").write_text("{")
    return ["train", "--scene", str(_scene_of(run)), "--out", str(run), *TINY_RUN_ARGS]


def _scene_of(run: Path) -> Path:
    return Path(json.loads((run / "config.json").read_text())["scene"]["path"])


def _train_link_in_run(folder: Path) -> list[str]:
    """A run folder whose model.pt is a link to a user's file elsewhere."""
    run = tiny_run(folder / "run")
    (folder / "mine.pt").write_bytes(MODEL_PT)
    (run / "model.pt").unlink()
    (run / "model.pt").symlink_to(folder / "mine.pt")
    return ["train", "--scene", str(_scene_of(run)), "--out", str(run), *TINY_RUN_ARGS]


def _train_out_file(folder: Path) -> list[str]:
    (folder / "R").write_text("my notes")
    return _train(folder, folder / "R")


def _long_path(folder: Path) -> Path:
    """A path of 10,000 characters: 40 folder names of 250 characters (each a legal name)."""
    return folder.joinpath(*(["d" * 250] * 40))


def _status_is(state: str, *words: str) -> Callable[[Path, int, str], Optional[str]]:
    def check(folder: Path, code: int, err: str) -> Optional[str]:
        st = json.loads((folder / "run" / "status.json").read_text())
        if st.get("state") != state or not all(w in st.get("message", "") for w in words):
            return f"status.json is {st.get('state')!r} ({st.get('message')!r}), expected {state!r}"
        return None if (folder / "run" / "checkpoint.pt").is_file() else "no checkpoint.pt"
    return check


def _sigterm_train(folder: Path) -> list[str]:
    """A long run that gets SIGTERM (from a thread of this process) once it is in its steps."""
    if threading.current_thread() is not threading.main_thread():
        raise RuntimeError("the SIGTERM case needs the main thread (signals go to it)")
    run = folder / "run"

    def ours() -> bool:
        return getattr(signal.getsignal(signal.SIGTERM), "__name__", "") == "on_sigterm"

    def fire() -> None:
        deadline = time.time() + 50
        while time.time() < deadline:
            if (run / "train_log.jsonl").exists() and ours():    # never the default handler: it would kill us
                os.kill(os.getpid(), signal.SIGTERM)
                return
            time.sleep(0.05)
    threading.Thread(target=fire, daemon=True).start()
    return ["train", "--scene", str(tiny_scene(folder / "scene")), "--out", str(run), "--method", "vanilla",
            "--preset", "cpu-small", "--set", "train.iterations=100000", "--set", "train.eval_every=0",
            "--set", "train.log_every=1", "--set", "train.checkpoint_every=0", "--no-progress", "--quiet"]


def _terminated_line(folder: Path, code: int, err: str) -> Optional[str]:
    last = ([ln for ln in err.splitlines() if ln.strip()] or [""])[-1]
    if "terminated (SIGTERM)" not in last:
        return f"last line {last[:200]!r} does not say terminated (SIGTERM)"
    return _status_is("interrupted", "SIGTERM")(folder, code, err)


def _report_mode(folder: Path, code: int, err: str) -> Optional[str]:
    """Atomically written files get a new file's mode (0666 less the umask), not mkstemp's 0600; the
    folder, a new folder's (0777 less the umask), not mkdtemp's 0700."""
    mask = os.umask(0o022)
    os.umask(mask)
    want = 0o666 & ~mask
    got = stat.S_IMODE(os.stat(folder / "P" / "index.html").st_mode)
    if got != want:
        return f"index.html has mode {got:o}, expected {want:o}"
    got = stat.S_IMODE(os.stat(folder / "P").st_mode)
    return None if got == 0o777 & ~mask else f"the report folder has mode {got:o}, expected {0o777 & ~mask:o}"


def _no_lock_named(folder: Path, code: int, err: str) -> Optional[str]:
    return "the line names the report's own lock" if "writer.lock" in err else None


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
    # train --out: a run folder is a run's, never a user's folder, the scene, the project or the store
    Hostile("output", "train --out a folder holding a user's env.json and model.pt", _train_users_files,
            ("R: holds files that are not a gsbench run's", "env.json"),
            check=_checks(_kept("R/env.json", '{"mine": true}'), _kept("R/model.pt", MODEL_PT),
                          _only("R", {"env.json", "model.pt"}))),
    Hostile("output", "train --out /", lambda f: _train(f, "/"), ("/: refused as a run folder", "root")),
    Hostile("output", "train --out the scene folder", _train_into_scene, ("refused as a run folder", "scene folder"),
            check=lambda f, c, e: "config.json written into the scene" if (f / "scene" / "config.json").exists()
            else None),
    Hostile("output", "train --out a folder inside the scene", _train_inside_scene, ("scene folder",),
            check=lambda f, c, e: "run written into the scene" if (f / "scene" / "images" / "run").exists() else None),
    Hostile("output", "train --out gsbench's project tree", _train_into_project, ("refused as a run folder",)),
    Hostile("output", "train --out inside a copy of the published store", _train_into_store,
            ("published results store",), check=_only("store", {"_shared", "lambda_grid-cpu"})),
    Hostile("output", "train --out a file", _train_out_file, ("R: exists and is not a folder",),
            check=_kept("R", "my notes")),
    Hostile("output", "train --out a run folder whose model.pt links to a user's file", _train_link_in_run,
            ("not a gsbench run's", "model.pt"), check=_kept("mine.pt", MODEL_PT)),
    Hostile("output", "train resumes an interrupted run (stale lock, leftover temporary file)", _train_resume,
            exit_code=0, check=_status_is("done")),
    Hostile("output", "SIGTERM during training: checkpoint, status interrupted, exit 143", _sigterm_train,
            exit_code=143, check=_terminated_line),
    # symbolic link loops, the root, long paths, file modes
    Hostile("output", "train --out a symbolic link loop", lambda f: _train(f, _loop(f)), ("loop",)),
    Hostile("output", "report --out a symbolic link loop", lambda f: _report(_loop(f)), ("loop",)),
    Hostile("output", "stress --out a symbolic link loop",
            lambda f: ["stress", "--component", "hostile:none", "--out", str(_loop(f))], ("loop",)),
    Hostile("output", "report --out / names no lock of its own", lambda f: _report(Path("/")), ("/: refused", "root"),
            check=_no_lock_named),
    Hostile("output", "train --out a 10,000-character path", lambda f: _train(f, _long_path(f)),
            ("ddd...ddd", "File name too long")),
    Hostile("output", "eval of a 10,000-character run path", lambda f: ["eval", str(_long_path(f))],
            ("ddd...ddd", "File name too long")),
    Hostile("output", "report files get a normal mode (umask), not 0600", lambda f: _report(f / "P"), exit_code=0,
            check=_report_mode),
    Hostile("output", "points --force keeps other files in sparse/0", _points_foreign, exit_code=0,
            check=_checks(_kept("scene/sparse/0/notes.txt", "my notes"),
                          lambda f, c, e: None if (f / "scene/sparse/points_provenance.json").is_file()
                          else "no points written")),
]
