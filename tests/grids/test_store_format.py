"""Store formats 2 and 3: parts most cells share are kept once under STORE/_shared/<hash>.json, and
(format 3) the per-view values are one column block. Records read back whole, a part is written once
for many cells, a hand-edited or missing part is refused naming the file, per-view values read back
bit for bit, a damaged column block is one line naming the file, format-1 and format-2 cells are
rewritten by `publish --upgrade` with the same content, and parts no cell uses are deleted.
Hand-made records, and the repository's own cells; nothing trained."""
from __future__ import annotations

import base64
import hashlib
import json
import math
import random
import zlib
from pathlib import Path

import pytest
from tiny_store import hand_record

from gsbench.errors import InputError
from gsbench.grids import store_columns
from gsbench.grids.store import read_store
from gsbench.grids.store_format import (
    SHARED_DIR,
    SHARED_PARTS,
    read_record,
    record_text,
    remove_unused_parts,
    write_record,
)
from gsbench.grids.store_upgrade import upgrade_store

REPO_STORE = Path(__file__).resolve().parents[2] / "results" / "cpu"


def _record(run_id: str, psnr: float, lr: float = 0.01) -> dict:
    return hand_record(run_id, psnr, lr, store_version=1)


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
    assert read_record(pa) == {**a, "store_version": 3} and read_record(pb) == {**b, "store_version": 3}


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
        assert json.loads(path.read_text())["store_version"] == 3
        assert read_record(path) == {**rec, "store_version": 3}
    assert sum(p.stat().st_size for p in (tmp_path / "g").glob("*.json")) < before
    assert len(upgrade_store(tmp_path, grids=[]).reformatted) == 0  # once rewritten, left alone


def test_parts_no_cell_uses_are_deleted(tmp_path):
    _write(tmp_path, _record("00000000000000aa", 20.5, lr=0.01))
    _write(tmp_path, _record("00000000000000aa", 20.5, lr=0.03))    # the cell replaced: its old train part unused
    assert len(list((tmp_path / SHARED_DIR).glob("*.json"))) == 5
    gone = remove_unused_parts(tmp_path)
    assert len(gone) == 1 and not gone[0].exists()
    assert read_record(tmp_path / "g" / "00000000000000aa.json")["config"]["train"]["lr"]["color"] == 0.03


# ----------------------------------------------------------------------------- format 3: per-view columns
AWKWARD = [-0.0, 5e-324, 1.7976931348623157e308, 0.1 + 0.2, 1.0, None, 2.220446049250313e-16, -123.456]


def _views(seed: int = 7, metrics: int = 12, views: int = 21) -> dict:
    """Per-view lists like a real cell's: random doubles, copies of a list, and awkward values."""
    rng = random.Random(seed)
    pv = {f"m{i:02d}": [rng.random() * 40 for _ in range(views)] for i in range(metrics)}
    pv["m00_decode"] = list(pv["m00"])
    pv["awkward"] = list(AWKWARD)
    return pv


def _with_views(run_id: str, per_view: dict) -> dict:
    rec = _record(run_id, 20.5)
    return {**rec, "results": {**rec["results"], "per_view": per_view}}


def test_per_view_values_read_back_bit_for_bit_from_a_column_block(tmp_path):
    rec = _with_views("00000000000000aa", _views())
    path = _write(tmp_path, rec)
    raw = json.loads(path.read_text())
    assert set(raw["results"]["per_view"]) == {"$columns"}
    got = read_record(path)
    assert got == {**rec, "store_version": 3}
    for k, values in rec["results"]["per_view"].items():          # -0.0 stays -0.0: same text, same bits
        assert [repr(v) for v in got["results"]["per_view"][k]] == [repr(v) for v in values]
    plain = len(record_text(rec["results"]["per_view"]))
    assert len(json.dumps(raw["results"]["per_view"])) < plain / 2


def test_a_non_finite_value_reads_as_null_and_an_integer_keeps_plain_lists(tmp_path):
    pv = _views()
    pv["m01"][3] = math.inf
    a = _write(tmp_path, _with_views("00000000000000aa", pv))
    assert read_record(a)["results"]["per_view"]["m01"][3] is None          # as the plain writer stores it
    pv = _views()
    pv["count"] = [3, 4, 5]
    b = _write(tmp_path, _with_views("00000000000000bb", pv))
    raw = json.loads(b.read_text())
    assert raw["results"]["per_view"]["count"] == [3, 4, 5] and "$columns" not in raw["results"]["per_view"]
    assert read_record(b)["results"]["per_view"] == pv


def _set_block(path: Path, data: bytes) -> None:
    raw = json.loads(path.read_text())
    raw["results"]["per_view"] = {"$columns": base64.b64encode(data).decode("ascii")}
    path.write_text(record_text(raw))


@pytest.mark.parametrize("damage, why", [
    (lambda text: text[:40] + ("A" if text[40] != "A" else "B") + text[41:], "(zlib: "),
    (lambda text: text[:-8], "(cut short"),
    (lambda text: text + "!", "not base64 text"),
    (lambda text: 12, "not base64 text"),
])
def test_a_damaged_column_block_is_one_line_naming_the_file(tmp_path, damage, why):
    path = _write(tmp_path, _with_views("00000000000000aa", _views()))
    raw = json.loads(path.read_text())
    raw["results"]["per_view"]["$columns"] = damage(raw["results"]["per_view"]["$columns"])
    path.write_text(record_text(raw))
    with pytest.raises(InputError, match=f"{path}: results.per_view is a column block that does not decode") as e:
        read_store(tmp_path)
    assert why in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("data, why", [
    (b'[["psnr",2]]\n' + b"\0" * 8, "8 bytes of values for 2 values"),
    (b'[["psnr",1],["psnr",1]]\n' + b"\0" * 16, "a metric named twice"),
    (b'{"psnr": 1}\n' + b"\0" * 8, "its first line is not a list of"),
    (b"\0" * 8, "no line of metric names"),
    (b'[["psnr",1]]\n' + bytes.fromhex("000000000000f07f"), "must be a finite number"),
])
def test_a_column_block_with_wrong_contents_is_refused(tmp_path, data, why):
    path = _write(tmp_path, _with_views("00000000000000aa", _views()))
    _set_block(path, zlib.compress(data))
    with pytest.raises(InputError, match=f"{path}: .*{why}"):
        read_record(path)


def test_a_column_block_that_unpacks_too_large_is_refused(tmp_path, monkeypatch):
    path = _write(tmp_path, _with_views("00000000000000aa", _views()))
    monkeypatch.setattr(store_columns, "MAX_JSON_BYTES", 1000)
    _set_block(path, zlib.compress(b'[["psnr",1000]]\n' + b"\0" * 8000))
    with pytest.raises(InputError, match=f"{path}: .*more than 1000 bytes unpacked"):
        read_record(path)


def test_upgrade_rewrites_format2_cells_as_columns_with_the_same_content(tmp_path):
    recs = [_with_views("00000000000000aa", _views(1)), _with_views("00000000000000bb", _views(2))]
    for rec in recs:                                       # format 2: shared parts, per-view values as plain lists
        path = tmp_path / "g" / f"{rec['run_id']}.json"
        write_record(tmp_path, path, rec)
        raw = {**json.loads(path.read_text()), "store_version": 2}
        raw["results"]["per_view"] = rec["results"]["per_view"]
        path.write_text(record_text(raw))
    before = sum(p.stat().st_size for p in (tmp_path / "g").glob("*.json"))
    report = upgrade_store(tmp_path, grids=[])
    assert len(report.reformatted) == 2 and report.refused == []
    for rec in recs:
        path = tmp_path / "g" / f"{rec['run_id']}.json"
        assert set(json.loads(path.read_text())["results"]["per_view"]) == {"$columns"}
        assert read_record(path) == {**rec, "store_version": 3}
    assert sum(p.stat().st_size for p in (tmp_path / "g").glob("*.json")) < 0.6 * before


def _refs_of(raw: dict) -> set[str]:
    return {raw[s][k]["$shared"] for s, k in SHARED_PARTS
            if isinstance(raw.get(s), dict) and isinstance(raw[s].get(k), dict) and set(raw[s][k]) == {"$shared"}}


@pytest.mark.skipif(not REPO_STORE.is_dir(), reason="no results/cpu in this checkout")
def test_the_repository_store_is_in_todays_format_with_no_unused_part():
    cells = read_store(REPO_STORE)
    raws = [json.loads(c.path.read_text()) for c in cells]
    assert {raw["store_version"] for raw in raws} == {3}
    assert all(set(raw["results"]["per_view"]) == {"$columns"} for raw in raws if raw["results"].get("per_view"))
    used: set[str] = set()
    for raw in raws:
        used |= _refs_of(raw)
    assert sorted(p.stem for p in (REPO_STORE / SHARED_DIR).glob("*.json")) == sorted(used)
    sizes = [c.path.stat().st_size for c in cells]
    assert sum(sizes) / len(sizes) < 12_000                 # issue 49: under 12 kB a cell on average


@pytest.mark.skipif(not REPO_STORE.is_dir(), reason="no results/cpu in this checkout")
def test_every_repository_cell_reads_back_equal_after_a_format3_write(tmp_path):
    """Every published record, written again in today's format into a fresh store, reads back equal,
    as objects and as text (so every float keeps its digits and -0.0 its sign)."""
    for c in read_store(REPO_STORE):
        path = tmp_path / c.grid / f"{c.run_id}.json"
        write_record(tmp_path, path, c.record)
        again = read_record(path)
        assert again == {**c.record, "store_version": 3}, c.path
        assert record_text(again) == record_text({**c.record, "store_version": 3}), c.path
