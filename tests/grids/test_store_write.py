"""Writing the published store safely (gsbench/grids/store_write.py), on hand-made records: the prune
never follows a link and deletes only parts the store wrote; a second writer is refused; a failing
write (a full disk) or a corrupt cell leaves the store as it was; stray temporaries are dropped and
ignored by git; every stored number is checked before a reader computes with it. Nothing trained."""
from __future__ import annotations

import errno
import json
import shutil
import socket
import subprocess
import time
from pathlib import Path

import pytest
from paths import REPO_ROOT
from tiny_store import hand_record

from gsbench.cli import main
from gsbench.errors import InputError
from gsbench.grids import store_format, store_write
from gsbench.grids.store import read_store
from gsbench.grids.store_format import SHARED_DIR, read_record, remove_unused_parts
from gsbench.grids.store_upgrade import upgrade_store
from gsbench.grids.store_write import StoreWriter
from gsbench.outdir import lock_path
from gsbench.runlock import RunLockedError
from gsbench.store import write_json_atomic


def _record(run_id: str, psnr: float, lr: float = 0.01) -> dict:
    return hand_record(run_id, psnr, lr, store_version=2)


AA, BB = "00000000000000aa", "00000000000000bb"


def _store(tmp_path: Path) -> Path:
    store = tmp_path / "store"
    with StoreWriter(store, "test") as w:
        w.commit([_record(AA, 20.5), _record(BB, 21.0)])
    return store


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _parts(store: Path) -> list[str]:
    return sorted(p.name for p in (store / SHARED_DIR).iterdir())


def test_a_commit_writes_whole_cells_and_leaves_nothing_beside_the_store(tmp_path):
    store = _store(tmp_path)
    assert [c.run_id for c in read_store(store)] == [AA, BB]
    assert read_record(store / "g" / f"{AA}.json")["results"]["metrics"] == {"psnr": 20.5}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["store"]       # no lock, no scratch folder
    assert not (store / store_write.SCRATCH_MARK).exists()


def test_the_prune_deletes_only_unused_parts_the_store_wrote(tmp_path):
    store = _store(tmp_path)
    (store / SHARED_DIR / "mine.json").write_text('{"my": "notes"}')
    (store / SHARED_DIR / "NOTES.json").write_text("[]")
    edited = store / SHARED_DIR / "0123456789abcdef.json"        # a part's name, not its content's hash
    edited.write_text("{}\n")
    old_train = json.loads((store / "g" / f"{AA}.json").read_text())["config"]["train"]["$shared"]
    with StoreWriter(store, "test") as w:                         # both cells get another train part
        pruned = w.commit([_record(AA, 20.5, lr=0.02), _record(BB, 21.0, lr=0.02)])
    assert [p.name for p in pruned] == [f"{old_train}.json"] and not pruned[0].exists()
    assert {"mine.json", "NOTES.json", edited.name} <= set(_parts(store))
    assert (store / SHARED_DIR / "mine.json").read_text() == '{"my": "notes"}'
    assert read_record(store / "g" / f"{BB}.json")["config"]["train"]["lr"]["color"] == 0.02


def _shared_elsewhere(tmp_path: Path, store: Path) -> Path:
    """STORE/_shared made a link to a folder elsewhere that also holds a user's mine.json."""
    elsewhere = tmp_path / "elsewhere"
    shutil.move(str(store / SHARED_DIR), str(elsewhere))
    (elsewhere / "mine.json").write_text("{}")
    (store / SHARED_DIR).symlink_to(elsewhere, target_is_directory=True)
    return elsewhere


def test_a_shared_folder_that_is_a_link_is_refused_by_publish_prune_and_upgrade(tmp_path):
    store = _store(tmp_path)
    elsewhere = _shared_elsewhere(tmp_path, store)
    before = _snapshot(elsewhere)
    with pytest.raises(InputError, match=f"{SHARED_DIR}: a symbolic link in the results store"):
        with StoreWriter(store, "test") as w:
            w.commit([_record(AA, 20.5, lr=0.5)])
    with pytest.raises(InputError, match=f"{SHARED_DIR}: a symbolic link"):
        remove_unused_parts(store)
    with pytest.raises(InputError, match=f"{SHARED_DIR}: a symbolic link"):
        upgrade_store(store, grids=[])
    assert _snapshot(elsewhere) == before and (elsewhere / "mine.json").exists()
    assert not lock_path(store).exists()


def test_a_part_that_is_a_link_is_refused(tmp_path):
    store = _store(tmp_path)
    part = sorted((store / SHARED_DIR).iterdir())[0]
    outside = tmp_path / "outside.json"
    shutil.move(str(part), str(outside))
    part.symlink_to(outside)
    with pytest.raises(InputError, match=f"{part.name}: a symbolic link"):
        remove_unused_parts(store)
    with pytest.raises(InputError, match=f"{part.name}: a symbolic link"):
        with StoreWriter(store, "test"):
            pass
    assert outside.exists()


def test_a_second_writer_is_refused_while_another_holds_the_lock(tmp_path):
    store = _store(tmp_path)
    before = _snapshot(store)
    lock = lock_path(store)                 # another live process's lock: pid 1 is alive and is not us
    lock.write_text(json.dumps({"pid": 1, "host": socket.gethostname(), "started": time.time(),
                                "command": "gsbench publish runs --to store", "token": "other"}))
    with pytest.raises(RunLockedError, match="another process is writing this results store: pid 1"):
        with StoreWriter(store, "second") as w:
            w.commit([_record(AA, 20.5, lr=0.9)])
    with pytest.raises(RunLockedError):
        upgrade_store(store, grids=[])
    assert _snapshot(store) == before and lock.exists()
    lock.unlink()
    with StoreWriter(store, "after") as w:            # released: the next writer gets it
        w.commit([_record(AA, 20.5, lr=0.9)])
    assert not lock.exists()


def test_a_full_disk_writes_nothing_and_says_so(tmp_path, monkeypatch):
    store = _store(tmp_path)
    before = _snapshot(store)
    calls = []
    real = store_format.write_text_atomic

    def full(path, text):
        calls.append(path)
        if len(calls) > 2:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        real(path, text)
    monkeypatch.setattr(store_format, "write_text_atomic", full)
    with pytest.raises(InputError, match="No space left on device.*nothing was written: the results store") as e:
        with StoreWriter(store, "test") as w:
            w.commit([_record(AA, 20.5, lr=0.3), _record(BB, 21.0, lr=0.4)])
    assert str(e.value).startswith(f"{store}/") and ".publish-" not in str(e.value)    # the store's path, not scratch
    assert _snapshot(store) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["store"]


def test_a_corrupt_unrelated_cell_stops_publish_before_it_writes(tmp_path, capsys):
    from gsbench.grids.store import read_store_to_write
    store = _store(tmp_path)
    (store / "other").mkdir()
    (store / "other" / "0000000000000ccc.json").write_text('{"store_version": 2, "grid"')
    before = _snapshot(store)
    with pytest.raises(InputError, match="0000000000000ccc.json: corrupt or truncated JSON.*; nothing was written"):
        with StoreWriter(store, "test"):
            read_store_to_write(store)
    assert _snapshot(store) == before


def test_stray_temporaries_are_dropped_and_git_ignores_them(tmp_path):
    store = _store(tmp_path)
    stray = store / "g" / f".{AA}.json.k2j4x_9a.tmp"
    stray.write_text('{"half": ')
    assert [c.run_id for c in read_store(store)] == [AA, BB]          # readers never read it
    with StoreWriter(store, "test") as w:
        w.commit([_record(AA, 20.5, lr=0.7)])
    assert not stray.exists() and [c.run_id for c in read_store(store)] == [AA, BB]
    if shutil.which("git") and (REPO_ROOT / ".git").exists():
        for rel in (f"results/cpu/g/.{AA}.json.k2j4x_9a.tmp", "results/.cpu.publish-123-abcd/x.json",
                    "results/.cpu.writer.lock", "results/cpu/.gsbench-publish"):
            out = subprocess.run(["git", "-C", str(REPO_ROOT), "check-ignore", "-q", "--no-index", rel])
            assert out.returncode == 0, f"{rel} is not ignored by .gitignore"


def test_a_scratch_folder_a_killed_writer_left_is_removed_by_the_next(tmp_path):
    store = _store(tmp_path)
    left = tmp_path / f"{store_write.scratch_prefix(store)}999-abc"
    (left / "g").mkdir(parents=True)
    (left / store_write.SCRATCH_MARK).write_bytes(b"")
    (left / "g" / f"{AA}.json").write_text("{}")
    unmarked = tmp_path / f"{store_write.scratch_prefix(store)}998-abc"      # not marked: not ours, kept
    unmarked.mkdir()
    (store / store_write.SCRATCH_MARK).write_bytes(b"")
    with StoreWriter(store, "test"):
        pass
    assert not left.exists() and unmarked.exists() and not (store / store_write.SCRATCH_MARK).exists()


# ----------------------------------------------------------------------------- stored numbers
def _edit_raw(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


@pytest.mark.parametrize("value, why", [
    ("9" * 401, "results.metrics.psnr must be a finite number or null, got an integer of 401 digits"),
    ('"20.5 dB"', "results.metrics.psnr must be a finite number or null, got a str ('20.5 dB')"),
    ("NaN", "results.metrics.psnr must be a finite number or null, got nan (not finite)"),
    ("true", "results.metrics.psnr must be a finite number or null, got a bool"),
])
def test_a_stored_metric_that_is_no_number_is_refused_naming_the_file(tmp_path, value, why):
    store = _store(tmp_path)
    path = store / "g" / f"{AA}.json"
    _edit_raw(path, '"psnr": 20.5', f'"psnr": {value}')
    with pytest.raises(InputError, match=f"{path}: " + why.replace("(", r"\(").replace(")", r"\)")):
        read_store(store)


def test_a_per_view_value_and_a_newer_results_version_are_refused(tmp_path):
    store = _store(tmp_path)
    path = store / "g" / f"{AA}.json"
    _edit_raw(path, '"psnr": [20.5, 20.5]', '"psnr": [20.5, 1e999]')
    with pytest.raises(InputError, match=r"results.per_view.psnr\[1\] must be a finite number or null"):
        read_record(path)
    _edit_raw(path, '"psnr": [20.5, 1e999]', '"psnr": [20.5, 20.5]')
    raw = json.loads(path.read_text())
    raw["results"]["results_version"] = 999
    path.write_text(json.dumps(raw))
    with pytest.raises(InputError, match="results version 999; this gsbench reads versions 1 to"):
        read_record(path)


def test_a_part_nested_100000_levels_deep_is_one_line(tmp_path):
    store = _store(tmp_path)
    path = store / "g" / f"{AA}.json"
    text = "[" * 100_000 + "]" * 100_000 + "\n"
    h = store_format._hash(text)
    (store / SHARED_DIR / f"{h}.json").write_text(text)              # named by its true hash
    raw = json.loads(path.read_text())
    raw["config"]["train"] = {"$shared": h}
    path.write_text(json.dumps(raw))
    with pytest.raises(InputError, match=f"{h}.json: refused: JSON nested deeper than"):
        read_record(path)


def test_the_command_line_prints_one_line_for_a_huge_metric(tmp_path, capsys):
    store = _store(tmp_path)
    _edit_raw(store / "g" / f"{AA}.json", '"psnr": 20.5', '"psnr": ' + "9" * 401)
    for argv in (["verify", str(store), "--cells", "1"], ["publish", "--status", str(store)],
                 ["publish", "--page", str(tmp_path / "p.md"), "--from", str(store)]):
        assert main(argv) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "Traceback" not in err[0] and "integer of 401 digits" in err[0], argv
    assert not (tmp_path / "p.md").exists()


def test_collect_refuses_a_huge_or_text_metric_and_a_newer_results_version(tmp_path, capsys):
    res = {"run_id": "r1", "method": "vanilla", "scene": "s", "metrics": {"psnr": 10 ** 400}}
    write_json_atomic(tmp_path / "runs" / "r1" / "results.json", res)
    assert main(["collect", str(tmp_path / "runs")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "metrics.psnr must be a number or null, got an integer of 401 digits" in err[0]
    write_json_atomic(tmp_path / "runs" / "r1" / "results.json", {**res, "metrics": {"psnr": "x" * 5000}})
    assert main(["collect", str(tmp_path / "runs")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "got a str ('xxxx" in err[0] and len(err[0]) < 400
    write_json_atomic(tmp_path / "runs" / "r1" / "results.json", {**res, "metrics": {"psnr": 1.0},
                                                                  "results_version": 999})
    assert main(["collect", str(tmp_path / "runs")]) == 1
    assert "results version 999; this gsbench reads versions 1 to" in capsys.readouterr().err
