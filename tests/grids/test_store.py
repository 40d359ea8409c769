"""The published results store on a tiny plan (one grid file, two vanilla cells of 3 steps): publish
adds finished cells, refuses an edited config or another numerics version (writing nothing), lists
stale cells, `gsbench claims` reuses a published cell without training it, and `gsbench verify`
re-runs a cell (exact on this CPU) and catches a tampered number."""
from __future__ import annotations

import importlib.metadata
import json
import shutil
import tempfile
from pathlib import Path

import pytest
import yaml
from tiny_store import TINY_GRID

from gsbench import grids
from gsbench.cli import main
from gsbench.collect import read_collected
from gsbench.grids import store as store_mod
from gsbench.grids.executors import SerialExecutor
from gsbench.grids.store_format import SHARED_DIR, read_record
from gsbench.numerics import NUMERICS_VERSION
from gsbench.store import read_json

GRID = TINY_GRID


def _write_grid(path: Path, iterations: int = 3) -> Path:
    raw = json.loads(json.dumps(GRID))
    raw["base"]["set"]["train.iterations"] = iterations
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def tiny_plan():
    """(grid file, runs folder with both cells finished); shared read-only (tests copy it to change it)."""
    root = Path(tempfile.mkdtemp(prefix="gsbench-store-test-"))
    grid_file = _write_grid(root / "tiny.yaml")
    runs = root / "runs"
    grids.run_grid(grids.load_grid(grid_file), runs, SerialExecutor(progress=False), log=lambda s: None)
    yield grid_file, runs
    shutil.rmtree(root, ignore_errors=True)


@pytest.fixture
def published(tiny_plan, tmp_path):
    grid_file, runs = tiny_plan
    store = tmp_path / "store"
    assert main(["publish", str(runs), "--to", str(store), "--grids", str(grid_file)]) == 0
    return grid_file, runs, store


def _cells(runs: Path) -> list[Path]:
    return sorted(p.parent for p in runs.glob("*/results.json"))


def _copy_runs(runs: Path, dest: Path) -> Path:
    shutil.copytree(runs, dest)
    return dest


def _sorted_everywhere(obj) -> bool:
    if isinstance(obj, dict):
        return list(obj) == sorted(obj) and all(_sorted_everywhere(v) for v in obj.values())
    if isinstance(obj, list):
        return all(_sorted_everywhere(v) for v in obj)
    return True


def test_publish_writes_one_sorted_json_per_cell(published, capsys):
    grid_file, runs, store = published
    files = sorted(store.rglob("*"))
    cells = _cells(runs)
    assert sorted(p.name for p in (store / "tiny").iterdir()) == sorted(f"{c.name}.json" for c in cells)
    assert {p.parent.name for p in files if p.is_file()} == {"tiny", SHARED_DIR}
    assert all(p.suffix == ".json" for p in files if p.is_file())          # no model, no checkpoint
    for cell in cells:
        path = store / "tiny" / f"{cell.name}.json"
        text = path.read_text()
        assert _sorted_everywhere(json.loads(text)) and text.startswith("{\n  \"cell\"")
        rec = read_record(path)
        assert len(text.encode()) < 64_000
        results = json.loads((cell / "results.json").read_text())
        assert rec["results"]["metrics"] == results["metrics"] and rec["config"] == results["config"]
        assert rec["train_summary"] == json.loads((cell / "train_summary.json").read_text())
        env = json.loads((cell / "env.json").read_text())
        prov = rec["provenance"]
        assert prov["gsbench_commit"] == env["git_sha"] and prov["numba"] == importlib.metadata.version("numba")
        assert prov["train_s"] == rec["train_summary"]["train_s"] and prov["eval_s"] == results["timings"]["eval_s"]
        assert prov["numba_threading_layer"] == rec["train_summary"]["numba_threading_layer"]
        assert rec["numerics_version"] == prov["numerics_version"] == NUMERICS_VERSION
        if Path("/proc/cpuinfo").exists():
            model = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                          if ln.startswith("model name")), None)
            assert model is None or prov["cpu_model"] == model
    before = {p: p.read_bytes() for p in files if p.is_file()}
    capsys.readouterr()
    assert main(["publish", str(runs), "--to", str(store), "--grids", str(grid_file)]) == 0
    assert "0 cells added, 0 replaced (older numerics version), 2 already published" in capsys.readouterr().out
    assert {p: p.read_bytes() for p in before} == before


def test_publish_refuses_an_edited_config_and_writes_nothing(tiny_plan, tmp_path, capsys):
    grid_file, runs = tiny_plan
    runs = _copy_runs(runs, tmp_path / "runs")
    edited = _cells(runs)[0]
    cfg = json.loads((edited / "config.json").read_text())
    cfg["train"]["iterations"] = 7
    (edited / "config.json").write_text(json.dumps(cfg))
    res = json.loads((edited / "results.json").read_text())
    res["config"] = cfg
    (edited / "results.json").write_text(json.dumps(res))
    store = tmp_path / "store"
    assert main(["publish", str(runs), "--to", str(store), "--grids", str(grid_file)]) == 1
    cap = capsys.readouterr()
    assert f"refused: {edited}: config.json is not the plan's config (train.iterations: 7, the plan's 3)" in cap.out
    assert cap.err.strip().splitlines()[-1].startswith("gsbench publish: error: ")
    assert "1 cells refused" in cap.err and "nothing was published" in cap.err
    assert not store.exists() or not any(store.rglob("*.json"))         # not even the good cell


def test_publish_refuses_another_numerics_version(tiny_plan, tmp_path, capsys):
    grid_file, runs = tiny_plan
    runs = _copy_runs(runs, tmp_path / "runs")
    old = _cells(runs)[1]
    env = json.loads((old / "env.json").read_text())
    env["numerics_version"] = NUMERICS_VERSION - 1
    (old / "env.json").write_text(json.dumps(env))
    store = tmp_path / "store"
    assert main(["publish", str(runs), "--to", str(store), "--grids", str(grid_file)]) == 1
    out = capsys.readouterr().out
    assert f"refused: {old}: trained at numerics version {NUMERICS_VERSION - 1}" in out
    assert not store.exists() or not any(store.rglob("*.json"))


def test_publish_refuses_runs_of_an_older_plan(tiny_plan, tmp_path, capsys):
    _, runs = tiny_plan
    changed = _write_grid(tmp_path / "tiny.yaml", iterations=4)     # today's plan: another base setting
    assert main(["publish", str(runs), "--to", str(tmp_path / "store"), "--grids", str(changed)]) == 1
    out = capsys.readouterr().out
    assert out.count("a finished run of study tiny-test that is no cell of today's plan") == 2
    assert not (tmp_path / "store").exists()


def test_stale_cells_are_listed(published, tmp_path, monkeypatch, capsys):
    grid_file, runs, store = published
    capsys.readouterr()
    assert main(["publish", "--status", str(store), "--grids", str(grid_file)]) == 0
    out = capsys.readouterr().out
    assert "2 published cells: 2 current, 0 stale" in out and "stale:" not in out
    # the plan changes (a grid's base setting): both published cells are no cell of it any more
    changed = _write_grid(tmp_path / "tiny.yaml", iterations=4)
    assert main(["publish", "--status", str(store), "--grids", str(changed)]) == 0
    out = capsys.readouterr().out
    assert "2 published cells: 0 current, 2 stale" in out
    assert out.count("not a cell of today's plan") == 2
    # the code's numerics version moves on: every cell is stale, whatever the plan
    monkeypatch.setattr(store_mod, "NUMERICS_VERSION", NUMERICS_VERSION + 1)
    assert main(["publish", "--status", str(store), "--grids", str(grid_file)]) == 0
    out = capsys.readouterr().out
    assert out.count(f"numerics version {NUMERICS_VERSION}, the code's is {NUMERICS_VERSION + 1}") == 2


def test_claims_reuses_published_cells_without_training(published, tmp_path, monkeypatch, capsys):
    grid_file, runs, store = published
    import gsbench.grids.claims_plan as claims_plan
    monkeypatch.setattr(claims_plan, "plan_grids", lambda quick=False, names=None: [grids.load_grid(grid_file)])
    trained: list[str] = []
    monkeypatch.setattr(grids.running, "_train_and_evaluate", lambda spec, run_dir, status: trained.append(run_dir))
    out = tmp_path / "claims"
    assert main(["claims", "--out", str(out), "--store", str(store), "--executor", "serial", "--no-progress"]) == 0
    assert trained == []
    assert "2 published cells reused" in capsys.readouterr().out
    collected = read_collected(next((out / "report").glob("collected.*")))      # the report read both cells
    assert sorted(set(collected["run_id"])) == [c.name for c in _cells(runs)]
    for cell in _cells(runs):
        here = out / cell.name
        assert grids.cell_state(here) == "done"
        assert not (here / "model.pt").exists() and not (here / "checkpoint.pt").exists()
        assert read_json(here / "results.json") == read_json(cell / "results.json")
        assert read_json(here / "cell_status.json")["published"] == str(store / "tiny" / f"{cell.name}.json")
    # and a second claims run finds them done (nothing materialised again, nothing trained)
    assert main(["claims", "--out", str(out), "--store", str(store), "--executor", "serial", "--no-progress"]) == 0
    assert trained == [] and "published cells reused" not in capsys.readouterr().out


def test_verify_exact_then_tampered(published, tmp_path, capsys):
    _, runs, store = published
    capsys.readouterr()
    assert main(["verify", str(store), "--cells", "1", "--seed", "0"]) == 0
    out = capsys.readouterr().out
    assert "exact (same CPU family" in out and "0 mismatched" in out and "psnr" in out
    for path in (store / "tiny").glob("*.json"):
        rec = json.loads(path.read_text())
        rec["results"]["metrics"]["psnr"] += 1e-9
        path.write_text(json.dumps(rec))
    assert main(["verify", str(store), "--cells", "1", "--seed", "0"]) == 1
    out = capsys.readouterr().out
    psnr = next(ln for ln in out.splitlines() if ln.strip().startswith("psnr "))
    assert psnr.rstrip().endswith("MISMATCH") and "1 mismatched" in out


def test_verify_on_another_cpu_judges_by_the_seed_spread(published, capsys, monkeypatch):
    """The same re-run on a faked CPU name: no exact comparison, each metric against its setting's seeds
    (the tiny plan has one seed per setting, so none is judged, and the output says so)."""
    from gsbench.grids import verify as verify_mod
    _, _, store = published
    monkeypatch.setattr(verify_mod, "cpu_facts", lambda: {"cpu_model": "Faked CPU 9000", "cpu_flags": "0" * 16,
                                                          "physical_cores": 2})
    capsys.readouterr()
    assert main(["verify", str(store), "--cells", "1", "--seed", "0"]) == 0
    out = capsys.readouterr().out
    assert "judged by the seed spread" in out and "this machine Faked CPU 9000" in out and "exact (same" not in out
    psnr = next(ln for ln in out.splitlines() if ln.strip().startswith("psnr "))
    assert psnr.rstrip().endswith("no seed spread") and "none (1)" in psnr
    assert "0 outside the seed spread" in out


def _as_layout1(store: Path, fake_id: str) -> tuple[Path, str, dict]:
    """One published cell rewritten as gsbench wrote it before the `semantic` section (d, the autoencoder
    and L_sem's switch in `gaussiands`), under another run id: (its file, its true id, its record)."""
    path = sorted(store.glob("tiny/*.json"))[0]
    rec = read_record(path)
    true_id, sem = rec["run_id"], rec["config"].pop("semantic")
    g = rec["config"]["gaussiands"]
    g["latent_dim"], g["autoencoder"], g["losses"]["sem"] = sem["latent_dim"], sem["autoencoder"], sem["loss"]
    rec["config"]["dropped"] = {("gaussiands.autoencoder" if k == "semantic" else k): v
                                for k, v in rec["config"]["dropped"].items()}
    rec["run_id"] = rec["config"]["run_id"] = rec["results"]["run_id"] = fake_id
    old = path.with_name(f"{fake_id}.json")
    old.write_text(store_mod.record_text(rec))
    path.unlink()
    return old, true_id, rec


def test_upgrade_rewrites_a_layout1_cell_under_todays_run_id(published, capsys):
    grid_file, _, store = published
    before = {p.name: read_record(p) for p in store.glob("tiny/*.json")}
    old, true_id, _ = _as_layout1(store, "00000000000000aa")
    assert main(["publish", "--status", str(store), "--grids", str(grid_file)]) == 0
    assert "stale: " in capsys.readouterr().out                       # the old layout's id is no cell of the plan
    assert main(["publish", "--upgrade", str(store), "--grids", str(grid_file)]) == 0
    assert f"-> {old.parent.name}/{true_id}" in capsys.readouterr().out and not old.exists()
    back = read_record(old.with_name(f"{true_id}.json"))
    assert back["provenance"].pop("upgraded")["from_run_id"] == "00000000000000aa"
    want = before[f"{true_id}.json"]
    assert back["results"] == want["results"] and back["run_id"] == true_id
    assert {k: v for k, v in back["config"].items() if k != "dropped"} == \
        {k: v for k, v in want["config"].items() if k != "dropped"}
    assert main(["publish", "--status", str(store), "--grids", str(grid_file)]) == 0
    assert "stale: " not in capsys.readouterr().out


def test_upgrade_refuses_a_cell_whose_config_is_not_the_plans(published, capsys):
    grid_file, _, store = published
    old, _, rec = _as_layout1(store, "00000000000000bb")
    rec["config"]["train"]["lr"]["color"] *= 2                        # not what the plan computes
    old.write_text(store_mod.record_text(rec))
    files = sorted(p.name for p in store.glob("tiny/*.json"))
    assert main(["publish", "--upgrade", str(store), "--grids", str(grid_file)]) == 1
    cap = capsys.readouterr()
    assert "is not the plan's (train.lr.color" in cap.out and "nothing was rewritten" in cap.err
    assert sorted(p.name for p in store.glob("tiny/*.json")) == files    # nothing rewritten
