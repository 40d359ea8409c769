"""Grid files: parsing, validation against the config tree, expansion, cell status."""
from __future__ import annotations

import math
import os
import socket
import subprocess
import time

import pytest

from gsbench import grids
from gsbench.errors import InputError
from gsbench.store import write_json_atomic

STUDIES = ["reconstruction", "ordering", "depth_formulation", "loss_subsets", "latent_dim", "lambda_grid",
           "depth_noise"]


def _grid(**kw):
    raw = {"study": "custom", "base": {"method": "gaussiands", "preset": "cpu-small"},
           "scenes": ["tabletop-small"], "seeds": [0]}
    raw.update(kw)
    return grids.parse_grid(raw, where="g.yaml")


@pytest.mark.parametrize("study", STUDIES)
@pytest.mark.parametrize("scale", ["cpu", "paper"])
def test_every_study_ships_at_both_scales(study, scale):
    g = grids.load_grid(f"{study}-{scale}")
    assert g.study == study
    assert set(g.axis_keys) <= set(grids.STUDIES[study])
    assert g.cells()


def test_study_cell_counts():
    ls = grids.load_grid("loss_subsets-cpu")
    subsets = {(c.overrides["gaussiands.losses.depth"], c.overrides["gaussiands.losses.tv"],
                c.overrides["gaussiands.losses.ds"]) for c in ls.cells()}
    assert len(ls.cells()) == 8 * 3 and len(subsets) == 8   # 8 subsets x seeds 0, 1, 2
    assert sorted({c.seed for c in ls.cells()}) == [0, 1, 2]
    ld = grids.load_grid("latent_dim-paper")
    dims = sorted(c.overrides["semantic.latent_dim"] for c in ld.cells() if c.method == "gaussiands")
    assert dims == [3, 6, 8, 12, 16, 32]
    assert [c.method for c in ld.cells()].count("vanilla") == 1
    dn = grids.load_grid("depth_noise-paper")
    kinds = {c.overrides.get("priors.depth.noise.type") for c in dn.cells()}
    assert kinds == {"gaussian", "poisson", "motion_blur", "salt_pepper", None}
    sev = {c.overrides["priors.depth.noise.severity"] for c in dn.cells()}
    assert sev == {0, 1, 2, 3, 4, 5}
    assert len(dn.cells()) == 2 * (4 * 5 + 1)   # two scenes x (4 kinds x 5 severities + clean)
    rec = grids.load_grid("reconstruction-cpu")
    assert sorted({c.method for c in rec.cells()}) == ["gaussiands", "grouping", "lift", "twostage", "vanilla"]


def test_lambda_sweeps_union_without_duplicate_default():
    g = grids.load_grid("lambda_grid-cpu")
    # 3x3 + 3x3 surfaces share the all-default cell (0.01, 5.0) == (1.5, 1.0): 17 distinct settings x 4 seeds
    assert len(g.cells()) == 17 * len(g.seeds) and len(g.seeds) == 4
    assert g.axis_keys == ["gaussiands.lambdas.depth", "gaussiands.lambdas.sem", "gaussiands.lambdas.tv",
                           "gaussiands.lambdas.ds"]


def test_product_and_zip():
    g = _grid(mode="zip", axes={"semantic.latent_dim": [3, 6], "gaussiands.losses.ds": [True, False]},
              seeds=[0, 1])
    combos = {(c.seed, c.overrides["semantic.latent_dim"], c.overrides["gaussiands.losses.ds"]) for c in g.cells()}
    assert combos == {(0, 3, True), (0, 6, False), (1, 3, True), (1, 6, False)}
    g = _grid(axes={"semantic.latent_dim": [3, 6], "gaussiands.losses.ds": [True, False]})
    assert len(g.cells()) == 4
    assert all(c.overrides["seed"] == 0 for c in g.cells())


def test_unknown_axis_key_names_the_closest():
    with pytest.raises(InputError, match=r"unknown config key 'semantic.latent_dims'.*semantic.latent_dim"):
        _grid(axes={"semantic.latent_dims": [3, 6]})
    with pytest.raises(InputError, match="unknown config key 'gaussiands.losses'"):
        _grid(axes={"gaussiands.losses": [True]})          # a subtree, not a leaf


def test_validation_errors():
    with pytest.raises(InputError, match="zip axes need equal lengths"):
        _grid(mode="zip", axes={"semantic.latent_dim": [3, 6], "gaussiands.losses.ds": [True]})
    with pytest.raises(InputError, match="must be true/false"):
        _grid(axes={"gaussiands.losses.ds": ["yes"]})
    with pytest.raises(InputError, match="must be a number"):
        _grid(axes={"semantic.latent_dim": ["3"]})
    with pytest.raises(InputError, match="non-empty list"):
        _grid(axes={"semantic.latent_dim": []})
    with pytest.raises(InputError, match="unknown top-level keys"):
        _grid(axis={"semantic.latent_dim": [3]})
    with pytest.raises(InputError, match="base.preset: unknown preset"):
        _grid(base={"preset": "gpu-huge"})
    with pytest.raises(InputError, match="study 'latent_dim' varies"):
        _grid(study="latent_dim", axes={"gaussiands.losses.ds": [True, False]})
    with pytest.raises(InputError, match="seeds"):
        _grid(axes={"seed": [0, 1]})
    with pytest.raises(InputError, match="no such file and not a shipped grid"):
        grids.load_grid("no-such-grid")


def test_later_seeds_are_declared_not_run_differently():
    g = _grid(seeds=[0, 1, 2, 3], later_seeds={"seeds": [2, 3], "why": "the first two left it unmarked"},
              axes={"semantic.latent_dim": [3, 6]})
    plain = _grid(seeds=[0, 1, 2, 3], axes={"semantic.latent_dim": [3, 6]})
    assert g.later_seeds == [2, 3] and g.later_why == "the first two left it unmarked" and plain.later_seeds == []
    assert [(c.seed, c.overrides) for c in g.cells()] == [(c.seed, c.overrides) for c in plain.cells()]
    for bad, match in (({"seeds": [4], "why": "x"}, "must be some, not all, of seeds"),
                       ({"seeds": [0, 1, 2, 3], "why": "x"}, "must be some, not all, of seeds"),
                       ({"seeds": [3], "why": " "}, "must say what the first look saw"),
                       ({"seeds": [3]}, "must be a mapping")):
        with pytest.raises(InputError, match=match):
            _grid(seeds=[0, 1, 2, 3], later_seeds=bad)


def test_set_cannot_override_an_axis():
    with pytest.raises(InputError, match="conflicts with the grid axis"):
        grids.load_grid("tiny-test", extra_set={"semantic.latent_dim": 8})
    g = grids.load_grid("tiny-test", extra_set={"train.iterations": 30})
    assert all(c.overrides["train.iterations"] == 30 for c in g.cells())


def test_scene_specs(tmp_path, monkeypatch):
    folder = tmp_path / "myscene"
    folder.mkdir()
    monkeypatch.setenv("MYDATA", str(tmp_path))
    g = _grid(scenes=["${MYDATA}/myscene", {"preset": "tabletop-small", "seed": 3, "resolution": [64, 48]}])
    specs = {c.scene.label for c in g.cells()}
    assert specs == {"myscene", "tabletop-small-3-64x48"}
    path_spec = [c.scene for c in g.cells() if c.scene.path][0]
    assert grids.resolve_scene(path_spec, tmp_path) == folder.resolve()
    monkeypatch.delenv("MYDATA")
    with pytest.raises(InputError):
        grids.resolve_scene(path_spec, tmp_path)


# ------------------------------------------------------------------------- status / stale detection
def _status(run_dir, **kw):
    write_json_atomic(run_dir / grids.CELL_STATUS_FILE, kw)


def test_cell_state(tmp_path):
    d = tmp_path / "cell"
    d.mkdir()
    assert grids.cell_state(d) == "pending"
    host = socket.gethostname()
    _status(d, state="running", pid=os.getpid(), host=host, heartbeat=time.time())
    assert grids.cell_state(d) == "running"
    dead = subprocess.Popen(["true"])
    dead.wait()
    _status(d, state="running", pid=dead.pid, host=host, heartbeat=time.time())
    assert grids.cell_state(d) == "stale"                      # killed worker: resumable
    _status(d, state="running", pid=1, host="other-node", heartbeat=time.time() - 10 * grids.STALE_AFTER_S)
    assert grids.cell_state(d) == "stale"                      # heartbeat too old on another node
    _status(d, state="running", pid=1, host="other-node", heartbeat=time.time())
    assert grids.cell_state(d) == "running"
    _status(d, state="done")
    assert grids.cell_state(d) == "stale"                      # no results.json: not finished
    (d / "results.json").write_text("{}")
    assert grids.cell_state(d) == "done"
    _status(d, state="failed", error="boom")
    assert grids.cell_state(d) == "failed"
    (d / grids.CELL_STATUS_FILE).write_text('{"state": "runn')  # torn file
    assert grids.cell_state(d) == "pending"


def test_format_status_counts():
    rows = [{"run_id": "a", "state": "done", "method": "m", "scene": "s", "seed": 0, "axes": "x=1", "wall_s": 1.5,
             "attempt": 1, "error": ""},
            {"run_id": "b", "state": "failed", "method": "m", "scene": "s", "seed": 0, "axes": "x=2", "wall_s": None,
             "attempt": 2, "error": "ValueError: bad"}]
    text = grids.format_status(rows)
    assert "2 cells: done 1, failed 1" in text
    assert "ValueError: bad" in text


def test_cli_list_dry_run_and_errors(capsys):
    from gsbench.cli import main
    assert main(["ablate", "--list"]) == 0
    out = capsys.readouterr().out
    for study in STUDIES:
        assert f"{study}-cpu" in out and f"{study}-paper" in out
    assert main(["ablate", "--grid", "loss_subsets-cpu", "--out", "x", "--dry-run"]) == 0
    assert "24 cells" in capsys.readouterr().out
    assert main(["ablate", "--grid", "tiny-test", "--out", "x", "--set", "semantic.latent_dims=3"]) == 1
    assert "did you mean semantic.latent_dim" in capsys.readouterr().err


def test_unknown_scene_name_is_an_error():
    with pytest.raises(InputError, match="neither a synthetic preset"):
        _grid(scenes=["tabletop-smal"])


def test_failed_cell_writes_failed_results_and_stays_failed(tmp_path, monkeypatch):
    """A failing cell leaves a results.json with status failed, null metrics and the error as the
    reason (reports: "n/a (run failed)"), and that record never makes the cell count as done."""
    from gsbench.collect import collect

    def boom(spec, run_dir, status):
        raise RuntimeError("simulated crash")

    from gsbench.grids import running
    monkeypatch.setattr(running, "_train_and_evaluate", boom)
    run_dir = tmp_path / "runs" / "abc123"
    spec = {"run_dir": str(run_dir), "scene_path": str(tmp_path / "no-such-scene"), "study": "custom",
            "axes": {"train.lambda_dssim": 0.2}, "scene": {"path": "x"}, "seed": 3, "method": "vanilla",
            "config": {"method": "vanilla", "seed": 3, "study": "custom", "grid": {"train.lambda_dssim": 0.2}}}
    out = grids.run_cell(spec)
    assert out["state"] == "failed"
    res = grids.read_json(run_dir / "results.json")
    assert res["status"] == "failed" and res["run_id"] == "abc123" and res["seed"] == 3
    assert res["method"] == "vanilla" and res["scene"] == "no-such-scene" and res["study"] == "custom"
    assert res["grid"] == {"train.lambda_dssim": 0.2}
    assert res["metrics"]["psnr"] is None and all(v is None for v in res["metrics"].values())
    assert any("simulated crash" in why for why in res["skipped"].values())
    assert grids.cell_state(run_dir) == "failed"
    # a failure record is never "done", even under a cell_status that claims so
    _status(run_dir, state="done")
    assert grids.cell_state(run_dir) == "stale"
    # collect: every metric row is NaN with the reason "run failed"
    df = collect(tmp_path / "runs")
    psnr = df[df["metric"] == "psnr"]
    assert len(psnr) == 1 and math.isnan(psnr["value"].iloc[0])
    assert psnr["status"].iloc[0] == "failed"
    assert psnr["reason"].iloc[0].startswith("run failed (attempt 1): RuntimeError: simulated crash")
    assert psnr["axis.train.lambda_dssim"].iloc[0] == 0.2


def test_pid_alive_counts_a_killed_unreaped_worker_as_dead():
    """Workers of a SIGKILLed grid can linger as zombies (nobody reaps them): they must read as
    dead so that a re-run resumes their cells instead of waiting for a fresh heartbeat."""
    import signal
    import subprocess
    import time

    from gsbench.grids import pid_alive

    p = subprocess.Popen(["sleep", "30"])
    try:
        assert pid_alive(p.pid)
        os.kill(p.pid, signal.SIGKILL)
        time.sleep(0.3)   # dead but not reaped: a zombie
        assert not pid_alive(p.pid)
    finally:
        p.kill()
        p.wait()
