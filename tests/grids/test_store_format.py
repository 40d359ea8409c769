"""Store format 2: parts most cells share are kept once under STORE/_shared/<hash>.json. Records read
back whole, a part is written once for many cells, a hand-edited or missing part is refused naming the
file, a format-1 cell is rewritten by `publish --upgrade` with the same content, and parts no cell
uses are deleted. Hand-made records; nothing trained."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from gsbench.errors import InputError
from gsbench.grids.store import read_store
from gsbench.grids.store_format import SHARED_DIR, read_record, record_text, remove_unused_parts, write_record
from gsbench.grids.store_upgrade import upgrade_store

REPO_STORE = Path(__file__).resolve().parents[2] / "results" / "cpu"


def _record(run_id: str, psnr: float, lr: float = 0.01) -> dict:
    return {"store_version": 1, "numerics_version": 1, "grid": "g", "study": "s", "run_id": run_id,
            "cell": {"method": "vanilla", "seed": 0, "scene": {"preset": "p"}, "axes": {}},
            "scene_fingerprint": "fp",
            "config": {"run_id": run_id, "train": {"iterations": 100, "lr": {"color": lr}}, "eval": {"previews": 2}},
            "results": {"run_id": run_id, "metrics": {"psnr": psnr}, "metric_impl": {"psnr": "psnr/v1"},
                        "frames": {"test": ["a.png", "b.png"]}, "per_view": {"psnr": [psnr, psnr]}},
            "train_summary": {"status": "done"}, "provenance": {"gsbench_commit": "abc"}}


def _write(store: Path, rec: dict) -> Path:
    path = store / rec["grid"] / f"{rec['run_id']}.json"
    write_record(store, path, rec)
    return path


def test_records_read_back_whole_and_parts_are_written_once(tmp_path):
    a, b = _record("00000000000000aa", 20.5), _record("00000000000000bb", 21.25)
    pa, pb = _write(tmp_path, a), _write(tmp_path, b)
    parts = sorted((tmp_path / SHARED_DIR).glob("*.json"))
    assert len(parts) == 4                          # config.train, config.eval, results.metric_impl, results.frames
    for p in parts:                                 # each named by the SHA-256 of its text
        assert p.stem == hashlib.sha256(p.read_bytes()).hexdigest()[:16]
    raw = json.loads(pa.read_text())
    assert set(raw["config"]["train"]) == {"$shared"} and raw["config"]["train"]["$shared"] in {p.stem for p in parts}
    assert raw["results"]["metrics"] == {"psnr": 20.5} and raw["results"]["per_view"] == {"psnr": [20.5, 20.5]}
    assert read_record(pa) == {**a, "store_version": 2} and read_record(pb) == {**b, "store_version": 2}


def test_a_cell_with_its_own_settings_gets_its_own_part(tmp_path):
    _write(tmp_path, _record("00000000000000aa", 20.5, lr=0.01))
    _write(tmp_path, _record("00000000000000bb", 20.5, lr=0.02))
    assert len(list((tmp_path / SHARED_DIR).glob("*.json"))) == 5
    assert read_record(tmp_path / "g" / "00000000000000bb.json")["config"]["train"]["lr"]["color"] == 0.02


def test_an_edited_part_is_refused_naming_it(tmp_path):
    path = _write(tmp_path, _record("00000000000000aa", 20.5))
    part = tmp_path / SHARED_DIR / f"{json.loads(path.read_text())['config']['train']['$shared']}.json"
    part.write_text(part.read_text().replace("100", "200"))
    with pytest.raises(InputError, match=f"{part}: its content no longer has the hash"):
        read_store(tmp_path)


def test_a_missing_part_is_refused_naming_the_cell(tmp_path):
    path = _write(tmp_path, _record("00000000000000aa", 20.5))
    part = tmp_path / SHARED_DIR / f"{json.loads(path.read_text())['results']['frames']['$shared']}.json"
    part.unlink()
    with pytest.raises(InputError, match=f"{path}: results.frames refers to shared part"):
        read_record(path)


def test_a_newer_store_version_is_refused(tmp_path):
    path = tmp_path / "g" / "00000000000000aa.json"
    path.parent.mkdir()
    path.write_text(record_text({**_record("00000000000000aa", 20.5), "store_version": 9}))
    with pytest.raises(InputError, match="store version 9"):
        read_record(path)


def test_upgrade_rewrites_format1_cells_with_the_same_content(tmp_path, capsys):
    recs = [_record("00000000000000aa", 20.5), _record("00000000000000bb", 21.0)]
    for rec in recs:                                                 # format 1: every part in the file
        path = tmp_path / "g" / f"{rec['run_id']}.json"
        path.parent.mkdir(exist_ok=True)
        path.write_text(record_text(rec))
    before = sum(p.stat().st_size for p in tmp_path.rglob("*.json"))
    report = upgrade_store(tmp_path, grids=[])
    assert len(report.reformatted) == 2 and report.upgraded == [] and report.refused == []
    for rec in recs:
        path = tmp_path / "g" / f"{rec['run_id']}.json"
        assert json.loads(path.read_text())["store_version"] == 2
        assert read_record(path) == {**rec, "store_version": 2}
    assert sum(p.stat().st_size for p in (tmp_path / "g").glob("*.json")) < before
    assert len(upgrade_store(tmp_path, grids=[]).reformatted) == 0  # once rewritten, left alone


def test_parts_no_cell_uses_are_deleted(tmp_path):
    _write(tmp_path, _record("00000000000000aa", 20.5, lr=0.01))
    _write(tmp_path, _record("00000000000000aa", 20.5, lr=0.03))    # the cell replaced: its old train part unused
    assert len(list((tmp_path / SHARED_DIR).glob("*.json"))) == 5
    gone = remove_unused_parts(tmp_path)
    assert len(gone) == 1 and not gone[0].exists()
    assert read_record(tmp_path / "g" / "00000000000000aa.json")["config"]["train"]["lr"]["color"] == 0.03


@pytest.mark.skipif(not REPO_STORE.is_dir(), reason="no results/cpu in this checkout")
def test_the_repository_store_is_in_todays_format_with_no_unused_part():
    cells = read_store(REPO_STORE)
    raw_versions = {json.loads(c.path.read_text())["store_version"] for c in cells}
    assert raw_versions == {2}
    used: set[str] = set()
    for c in cells:
        used |= {v["$shared"] for section in ("config", "results")
                 for v in json.loads(c.path.read_text())[section].values()
                 if isinstance(v, dict) and set(v) == {"$shared"}}
    assert sorted(p.stem for p in (REPO_STORE / SHARED_DIR).glob("*.json")) == sorted(used)
