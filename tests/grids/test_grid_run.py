"""Running grids: skip finished cells, resume stale ones, retry failed ones; the kill-and-resume
check through `gsbench ablate --jobs 2`, and the submitit executor in its local mode."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
import yaml

from gsbench import grids
from gsbench.grids.executors import SerialExecutor
from gsbench.store import read_json, write_json_atomic


@pytest.fixture
def own_tmp():
    """A temp folder outside pytest's basetemp: concurrent pytest sessions on a shared machine rotate
    (delete) old basetemps, which must not happen under a long-running grid."""
    d = Path(tempfile.mkdtemp(prefix="gsbench-grid-test-"))
    yield d
    shutil.rmtree(d, ignore_errors=True)


TINY_SCENE = {"preset": "tabletop-small", "views": 9, "resolution": [32, 24]}


def _write_grid(path: Path, **kw) -> Path:
    raw = {"study": "tiny-test", "base": {"method": "vanilla", "preset": "cpu-small",
                                          "set": {"train.iterations": 5, "train.max_width": 32}},
           "scenes": [TINY_SCENE], "seeds": [0],
           "axes": {"train.lr.color": [0.0025, 0.005], "train.lambda_dssim": [0.2, 0.0]}}
    raw.update(kw)
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


# ------------------------------------------------------------------------- machinery (fake runner)
def test_skip_failed_retry_and_stale(tmp_path, monkeypatch):
    calls: list[str] = []
    fail = {"on": None}

    def fake(spec, run_dir, status):
        calls.append(run_dir.name)
        if run_dir.name == fail["on"]:
            raise RuntimeError("simulated failure")
        write_json_atomic(run_dir / "results.json", {"metrics": {}})

    monkeypatch.setattr(grids.running, "_train_and_evaluate", fake)
    grid = grids.load_grid(_write_grid(tmp_path / "g.yaml"))
    out = tmp_path / "runs"
    planned = grids.plan(grid, out)
    ids = [pc.run_id for pc in planned]
    assert len(set(ids)) == 4
    assert (out / "scenes" / "tabletop-small-0-32x24-v9").is_dir()          # preset generated once
    fail["on"] = ids[1]
    rep = grids.run_grid(grid, out, SerialExecutor(progress=False), log=lambda s: None)
    assert sorted(rep.dispatched) == sorted(ids) and sorted(calls) == sorted(ids)
    st = read_json(out / ids[1] / grids.CELL_STATUS_FILE)
    assert st["state"] == "failed" and "simulated failure" in st["error"] and "Traceback" in st["traceback"]
    failed_res = read_json(out / ids[1] / "results.json")  # a failure record for the reports
    assert failed_res["status"] == "failed" and any(
        "simulated failure" in why for why in failed_res["skipped"].values()
    )

    # re-run: finished cells and the failed one are left alone
    calls.clear()
    rep = grids.run_grid(grid, out, SerialExecutor(progress=False), log=lambda s: None)
    assert rep.dispatched == [] and calls == []

    # --retry-failed runs only the failed cell
    fail["on"] = None
    rep = grids.run_grid(grid, out, SerialExecutor(progress=False), retry_failed=True, log=lambda s: None)
    assert rep.dispatched == [ids[1]] and calls == [ids[1]]
    assert read_json(out / ids[1] / grids.CELL_STATUS_FILE)["attempt"] == 2
    assert read_json(out / ids[1] / "results.json") == {"metrics": {}}   # the retry's results replace it

    # a cell whose worker died (running, dead pid) is stale and runs again; a live one is not touched
    calls.clear()
    dead = subprocess.Popen(["true"])
    dead.wait()
    write_json_atomic(out / ids[2] / grids.CELL_STATUS_FILE,
                      {"state": "running", "pid": dead.pid, "host": os.uname().nodename, "heartbeat": time.time()})
    write_json_atomic(out / ids[3] / grids.CELL_STATUS_FILE,
                      {"state": "running", "pid": os.getpid(), "host": os.uname().nodename, "heartbeat": time.time()})
    rep = grids.run_grid(grid, out, SerialExecutor(progress=False), log=lambda s: None)
    assert calls == [ids[2]]

    # status table: from the grid plan, and from the folder alone
    rows = grids.status_rows(out, grid)
    assert sorted(r["state"] for r in rows) == ["done", "done", "done", "running"]
    assert len(grids.status_rows(out)) == 4
    manifest = json.loads((out / "grid-g.json").read_text())
    assert sorted(c["run_id"] for c in manifest["cells"]) == sorted(ids)
    assert manifest["axis_keys"] == ["train.lr.color", "train.lambda_dssim"]


class RecordingExecutor:
    """Records every map call's items and runs them one after another (the fake runner below)."""

    def __init__(self) -> None:
        self.calls: list[list[str]] = []

    def map(self, fn, items):
        items = list(items)
        self.calls.append([Path(it["run_dir"]).name for it in items])
        return [fn(it) for it in items]


def test_grids_go_to_the_executor_as_one_dispatch(tmp_path, monkeypatch):
    """gsbench claims hands every grid's pending cells to the executor in one list, so no worker waits
    for a grid's last cell; each grid's report holds its own cells' results, in order."""
    monkeypatch.setattr(grids.running, "_train_and_evaluate",
                        lambda spec, run_dir, status: write_json_atomic(run_dir / "results.json", {"metrics": {}}))
    a = grids.load_grid(_write_grid(tmp_path / "a.yaml"))
    b = grids.load_grid(_write_grid(tmp_path / "b.yaml", study="tiny-b",
                                    axes={"train.lr.color": [0.001, 0.002, 0.003]}))
    out = tmp_path / "runs"
    ids = [[pc.run_id for pc in grids.plan(g, out)] for g in (a, b)]
    ex = RecordingExecutor()
    reps = grids.run_grids([a, b], out, ex, log=lambda s: None)
    assert ex.calls == [ids[0] + ids[1]]
    assert [rep.dispatched for rep in reps] == ids
    for rep, grid_ids in zip(reps, ids):
        assert [Path(r["run_dir"]).name for r in rep.results] == grid_ids
        assert all(r["state"] == "done" for r in rep.results)
    again = grids.run_grids([a, b], out, ex, log=lambda s: None)      # all done: nothing dispatched
    assert [rep.dispatched for rep in again] == [[], []] and len(ex.calls) == 1


def test_a_cell_two_grids_plan_runs_once(tmp_path, monkeypatch):
    """Grid by grid, the second grid found the first's cell done; in one dispatch the cell must still run
    once (two workers would race for its folder), and both grids' reports hold its result."""
    monkeypatch.setattr(grids.running, "_train_and_evaluate",
                        lambda spec, run_dir, status: write_json_atomic(run_dir / "results.json", {"metrics": {}}))
    a = grids.load_grid(_write_grid(tmp_path / "a.yaml"))
    twin = grids.load_grid(_write_grid(tmp_path / "twin.yaml"))
    out = tmp_path / "runs"
    ids = [pc.run_id for pc in grids.plan(a, out)]
    assert [pc.run_id for pc in grids.plan(twin, out)] == ids
    ex = RecordingExecutor()
    reps = grids.run_grids([a, twin], out, ex, log=lambda s: None)
    assert ex.calls == [ids]
    for rep in reps:
        assert [Path(r["run_dir"]).name for r in rep.results] == ids and all(r["state"] == "done" for r in rep.results)


def test_cell_configs_share_cache_and_record_grid(tmp_path):
    grid = grids.load_grid(_write_grid(tmp_path / "g.yaml"))
    planned = grids.plan(grid, tmp_path / "runs")
    caches = {pc.config["priors"]["cache_dir"] for pc in planned}
    assert caches == {str((tmp_path / "runs" / ".gsbench_cache").resolve())}
    grids_rec = [pc.config["grid"] for pc in planned]
    assert {(g["train.lr.color"], g["train.lambda_dssim"]) for g in grids_rec} == {
        (0.0025, 0.2), (0.0025, 0.0), (0.005, 0.2), (0.005, 0.0)}
    assert all(pc.config["study"] == "tiny-test" and pc.config["train"]["iterations"] == 5 for pc in planned)
    # the same grid in the same folder gives the same run ids (a re-run finds its cells)
    again = grids.plan(grid, tmp_path / "runs")
    assert [pc.run_id for pc in again] == [pc.run_id for pc in planned]


def test_status_before_any_run_is_pending(tmp_path):
    grid = grids.load_grid(_write_grid(tmp_path / "g.yaml"))
    (tmp_path / "runs").mkdir()
    rows = grids.status_rows(tmp_path / "runs", grid)        # scenes not generated yet: nothing created
    assert [r["state"] for r in rows] == ["pending"] * 4
    assert not (tmp_path / "runs" / "scenes").exists()


# ------------------------------------------------------------------------- real runs
def _gsbench(*args: str) -> list[str]:
    return [sys.executable, "-m", "gsbench.cli", *args]


def _done_cells(out: Path) -> list[Path]:
    done = []
    for st in out.glob(f"*/{grids.CELL_STATUS_FILE}"):
        try:
            if json.loads(st.read_text()).get("state") == "done":
                done.append(st.parent)
        except ValueError:
            pass
    return done


def _write_tiny_gaussiands_grid(path: Path, latent_dims: list[int]) -> Path:
    """The shipped tiny-test grid (GaussianDS, latent d x L_ds) on the 32x24 tabletop with one seed and a
    10-epoch autoencoder: the executor tests below need a few real semantic cells, not the shipped scale
    (21 views at 128x96, 500 autoencoder epochs, 8 cells: ~12 s a cell on 2 cores)."""
    raw = {"study": "tiny-test", "base": {"method": "gaussiands", "preset": "cpu-small",
                                          "set": {"train.eval_every": 100, "train.checkpoint_every": 100,
                                                  "semantic.autoencoder.epochs": 10}},
           "scenes": [TINY_SCENE], "seeds": [0], "mode": "product",
           "axes": {"semantic.latent_dim": latent_dims, "gaussiands.losses.ds": [True, False]}}
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


def _snapshot(d: Path) -> dict:
    return {name: ((d / name).stat().st_mtime_ns, (d / name).read_bytes())
            for name in ("results.json", "train_log.jsonl", "model.pt", "checkpoint.pt") if (d / name).exists()}


@pytest.mark.slow
def test_vanilla_cell_real_results(tmp_path):
    """One real cell (vanilla, 5 iterations) run in-process: results.json follows the schema."""
    grid = grids.load_grid(_write_grid(tmp_path / "g.yaml", axes={"train.lambda_dssim": [0.2]}))
    rep = grids.run_grid(grid, tmp_path / "runs", SerialExecutor(progress=False), log=lambda s: None)
    assert [r["state"] for r in rep.results] == ["done"], rep.results
    res = read_json(tmp_path / "runs" / rep.dispatched[0] / "results.json")
    for key in ("run_id", "method", "scene", "scene_path", "seed", "study", "grid", "config", "providers", "backend",
                "protocol", "metric_impl", "metrics", "per_view", "view_names", "skipped", "timings", "memory",
                "machine", "status", "dropped"):
        assert key in res, key
    assert res["study"] == "tiny-test" and res["grid"] == {"train.lambda_dssim": 0.2}
    assert res["method"] == "vanilla" and res["status"] == "done"
    assert len(res["per_view"]["psnr"]) == len(res["view_names"]) == 2      # views 0 and 8 of 9 are test views
    assert 5.0 < res["metrics"]["psnr"] < 60.0
    assert res["metrics"]["fps"] > 0 and res["timings"]["train_s"] > 0 and res["memory"]["peak_rss_mb"] > 0
    # vanilla has no semantic field: segmentation and removal are skipped with reasons, values null
    assert res["metrics"]["miou_3dovs"] is None and "miou_3dovs_encode" in res["skipped"]
    assert "removal_residual" in res["skipped"] and res["metrics"].get("removal_residual") is None
    assert res["metrics"]["lpips"] is None or res["metric_impl"]["lpips"]
    assert "lpips" in res["metric_impl"] or "lpips" in res["skipped"]


@pytest.mark.slow
def test_ablate_kill_and_resume(own_tmp):
    """A tiny grid of 3 cells (vanilla, 10 iterations at 32 px) with --jobs 2: SIGKILL the whole process
    group once some but not all cells are done, re-run, and check that finished cells were not re-trained
    and all end done. (What is checked is the grid machinery, the same for every method: vanilla cells
    need no priors or autoencoder, and 3 cells on 2 workers leave 1 or 2 for the re-run: one round.)"""
    out = own_tmp / "runs"
    grid = str(_write_grid(own_tmp / "g.yaml", axes={"train.lr.color": [0.0025, 0.005, 0.01]}))
    sets = ["--set", "train.iterations=10", "train.max_width=32"]
    args = _gsbench("ablate", "--grid", grid, "--out", str(out), "--jobs", "2", *sets, "--no-progress")
    log = open(own_tmp / "first.log", "w")
    proc = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    deadline = time.time() + 1500
    done: list[Path] = []
    while time.time() < deadline:
        done = _done_cells(out)
        if done:
            break
        if proc.poll() is not None:
            pytest.fail(f"ablate exited ({proc.returncode}) before any cell finished: "
                        + (own_tmp / "first.log").read_text()[-2000:])
        time.sleep(0.2)
    assert done, "no cell finished in time"
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    log.close()
    done = _done_cells(out)
    assert 1 <= len(done) < 3, f"{len(done)} cells done when killed; the test needs a partial grid"
    before = {d.name: _snapshot(d) for d in done}
    unfinished = [d for d in out.iterdir() if (d / grids.CELL_FILE).exists() and d not in done]

    rerun = subprocess.run(args, capture_output=True, text=True, timeout=3000)
    assert rerun.returncode == 0, rerun.stdout[-3000:] + rerun.stderr[-3000:]
    assert f"dispatching {3 - len(before)}" in rerun.stdout
    assert len(_done_cells(out)) == 3
    for name, snap in before.items():
        assert _snapshot(out / name) == snap, f"finished cell {name} was touched by the re-run"
        assert read_json(out / name / grids.CELL_STATUS_FILE)["attempt"] == 1
    for d in unfinished:                      # started before the kill: resumed in a second attempt
        st = read_json(d / grids.CELL_STATUS_FILE)
        assert st["state"] == "done" and st["attempt"] == 2
    status = subprocess.run(_gsbench("ablate", "--status", "--grid", grid, "--out", str(out), *sets),
                            capture_output=True, text=True)
    assert status.returncode == 0 and "3 cells: done 3" in status.stdout


@pytest.mark.slow
def test_ablate_submitit_local(own_tmp):
    """The tiny grid with one latent d (2 cells: a job array of 2) through the submitit executor in its
    local mode."""
    out = own_tmp / "runs"
    grid = str(_write_tiny_gaussiands_grid(own_tmp / "tiny.yaml", [3]))
    r = subprocess.run(_gsbench("ablate", "--grid", grid, "--out", str(out), "--executor", "submitit",
                                "--cluster", "local", "--timeout-min", "60",
                                "--set", "train.iterations=10", "train.max_width=32", "--no-progress"),
                       capture_output=True, text=True, timeout=3000)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "2 cells: done 2" in r.stdout
    cells = [d for d in out.iterdir() if (d / grids.CELL_FILE).exists()]
    assert len(cells) == 2
    pids = set()
    for d in cells:
        res = read_json(d / "results.json")
        assert res["study"] == "tiny-test" and set(res["grid"]) == {"semantic.latent_dim", "gaussiands.losses.ds"}
        assert res["config"]["train"]["iterations"] == 10
        m = res["metrics"]
        # a synthetic scene supports both protocols; both query modes are evaluated and named
        assert res["protocols"] == ["3dovs", "lerf"]
        for name in ("miou_3dovs_encode", "miou_3dovs_decode", "mbiou_3dovs_encode", "mbiou_3dovs_decode",
                     "miou_lerf_encode", "miou_lerf_decode", "removal_residual", "removal_psnr_outside",
                     "ordering_adjacent_distance", "ordering_adjacent_mask_iou"):
            assert m[name] is not None, name
            assert name in res["metric_impl"], name
        for name in ("miou_3dovs", "mbiou_3dovs", "miou_lerf"):
            assert m[name] == m[f"{name}_{res['query_mode']}"]
            assert 0.0 <= m[name] <= 1.0
        assert 0.0 <= m["removal_residual"] <= 1.0
        # the L_ds edge map's coverage travels from the train summary to results.json (none with L_ds off)
        info = read_json(d / "train_summary.json")["info"]
        if res["grid"]["gaussiands.losses.ds"]:
            assert m["ds_edge_fraction"] == info["edge_fraction"] and "ds_edge_fraction" in res["metric_impl"]
        else:
            assert m["ds_edge_fraction"] is None and "L_ds off" in res["skipped"]["ds_edge_fraction"]
        assert res["providers"]["depth"] and res["providers"]["masks"] and res["providers"]["features"]
        pids.add(read_json(d / grids.CELL_STATUS_FILE)["pid"])
    assert os.getpid() not in pids and (out / ".submitit").is_dir()


def test_priors_requests_group_cells_that_share_priors(own_tmp):
    grid = grids.load_grid(_write_grid(
        own_tmp / "g.yaml", base={"method": "gaussiands", "preset": "cpu-small",
                                   "set": {"train.iterations": 5, "train.max_width": 32}},
        axes={"semantic.latent_dim": [3, 6], "gaussiands.losses.tv": [True, False]},
        extra_cells=[{"method": "vanilla"}, {"method": "twostage"}, {"priors.ordering": "random"}]))
    planned = grids.plan(grid, own_tmp / "runs")
    reqs = {pc.cell.method + str(pc.cell.axes): grids.priors_request(pc.spec()) for pc in planned}
    gaussiands = [json.dumps(r, sort_keys=True) for k, r in reqs.items()
                  if k.startswith("gaussiands") and "random" not in k]
    assert len(gaussiands) == 4 and len(set(gaussiands)) == 1   # d and L_tv do not change the priors
    assert reqs["vanilla{'method': 'vanilla'}"] is None
    two = reqs["twostage{'method': 'twostage'}"]
    assert two["per_frame"] is True and two["need_depth"] is False
    rnd = [r for k, r in reqs.items() if "random" in k][0]
    assert rnd["priors"]["ordering"] == "random" and json.dumps(rnd, sort_keys=True) not in gaussiands


def test_shared_autoencoder_fits_are_the_ones_the_cells_restore(own_tmp):
    """d = 3 and d = 6, each with L_tv on and off: two fits for four cells, made before the cells; the
    cells find them (no cell adds an entry of its own) and each restores its fit."""
    grid = grids.load_grid(_write_grid(
        own_tmp / "g.yaml", base={"method": "gaussiands", "preset": "cpu-small",
                                   "set": {"train.iterations": 5, "train.max_width": 32,
                                           "semantic.autoencoder.epochs": 5}},
        axes={"semantic.latent_dim": [3, 6], "gaussiands.losses.tv": [True, False]},
        extra_cells=[{"method": "vanilla"}]))
    planned = grids.plan(grid, own_tmp / "runs")
    fits = [grids.autoencoder_request(pc.config, grids.priors_request(pc.spec())) for pc in planned]
    assert sum(f is None for f in fits) == 1                             # vanilla fits none
    assert len({json.dumps(f, sort_keys=True) for f in fits if f is not None}) == 2
    lines = []
    rep = grids.run_grid(grid, own_tmp / "runs", SerialExecutor(progress=False), log=lines.append)
    assert all(r["state"] == "done" for r in rep.results), rep.results
    assert any(line.startswith("shared autoencoder fits: 2 for 4 cells") for line in lines), lines
    entries = [p for p in (own_tmp / "runs" / ".gsbench_cache" / "autoencoder").iterdir()
               if not p.name.startswith(".")]
    assert len(entries) == 2
