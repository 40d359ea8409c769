"""gsbench collect: results.json files (hand-written, no training) -> one long table."""
from __future__ import annotations

import builtins
import json
import math
from pathlib import Path

import pandas as pd
import pytest
from report_runs import make_ablations, make_main, write_run

from gsbench.cli import main
from gsbench.collect import BASE_COLUMNS, collect, missing_reason, read_collected, write_collected
from gsbench.errors import InputError

INTERFACE = BASE_COLUMNS + ["metric", "value", "metric_impl"]


@pytest.fixture()
def runs(tmp_path: Path) -> Path:
    root = tmp_path / "runs"
    make_main(root)
    make_ablations(root)
    return root


def _v(df: pd.DataFrame, run: str, metric: str) -> pd.Series:
    sel = df[(df["run_id"] == f"id-{run}") & (df["metric"] == metric)]
    assert len(sel) == 1, (run, metric, len(sel))
    return sel.iloc[0]


def test_long_table_columns_rows_and_values(runs: Path):
    df = collect(runs)
    for c in INTERFACE:
        assert c in df.columns
    assert df["run_id"].nunique() == 8 + 8 + 5 + 3 + 4
    # vanilla on bench: 5 metrics + train_s (timings) + peak_rss_mb (memory) = 7 rows
    assert (df["run_id"] == "id-main/vanilla_bench").sum() == 7
    r = _v(df, "main/gds_bench_s1", "psnr")
    assert r["value"] == 26.0 and r["seed"] == 1 and r["method"] == "gaussiands" and r["scene"] == "bench"
    assert r["protocol"] == "3dovs" and r["backend"] == "torch" and r["provider.masks"] == "simulated-flow"
    assert r["metric_impl"] == "gsbench.psnr.uint8.v1"
    assert r["run_dir"] == str(runs / "main" / "gds_bench_s1")
    t = _v(df, "main/gds_bench_s1", "train_s")
    assert t["value"] == 120.0 and t["source"] == "timings"
    assert _v(df, "lat/d8", "peak_rss_mb")["value"] == 600.0


def test_missing_values_are_nan_with_reason(runs: Path):
    df = collect(runs)
    lp = _v(df, "main/vanilla_bench", "lpips")
    assert math.isnan(lp["value"]) and lp["reason"] == "no LPIPS weights"
    mi = _v(df, "main/vanilla_bench", "miou_3dovs")
    assert math.isnan(mi["value"]) and mi["reason"] == "method has no semantic field"
    assert _v(df, "main/vanilla_bench", "psnr")["reason"] is None


def test_axis_columns_are_typed(runs: Path):
    df = collect(runs)
    assert str(df["axis.gaussiands.losses.depth"].dtype) == "boolean"
    assert df["axis.semantic.latent_dim"].dtype == "float64"
    assert _v(df, "lat/d16", "psnr")["axis.semantic.latent_dim"] == 16.0
    assert _v(df, "ord/pose", "psnr")["axis.priors.ordering"] == "pose"
    # runs outside a study have no axis value
    assert pd.isna(_v(df, "main/gds_sofa", "psnr")["axis.priors.ordering"])
    assert _v(df, "loss/101", "psnr")["axis.gaussiands.losses.tv"] == False  # noqa: E712


def test_parquet_round_trip(runs: Path):
    df = collect(runs)
    out = write_collected(df, runs)
    assert out.name == "collected.parquet" and out.read_bytes()[:4] == b"PAR1"
    back = read_collected(out)
    assert len(back) == len(df)
    r = back[(back["run_id"] == "id-loss/110") & (back["metric"] == "psnr")].iloc[0]
    assert r["value"] == 23.0 and r["axis.gaussiands.losses.depth"] == True  # noqa: E712
    assert r["axis.gaussiands.losses.ds"] == False  # noqa: E712


def test_csv_fallback_without_pyarrow(runs: Path, monkeypatch):
    real_import = builtins.__import__

    def no_pyarrow(name, *a, **k):
        if name == "pyarrow" or name.startswith("pyarrow."):
            raise ImportError("no pyarrow (test)")
        return real_import(name, *a, **k)

    df = collect(runs)
    monkeypatch.setattr(builtins, "__import__", no_pyarrow)
    out = write_collected(df, runs)
    monkeypatch.undo()
    assert out.name == "collected.csv" and not (runs / "collected.parquet").exists()
    back = read_collected(out)
    r = back[(back["run_id"] == "id-lat/d8") & (back["metric"] == "miou_lerf")].iloc[0]
    assert r["value"] == pytest.approx(0.63) and r["axis.semantic.latent_dim"] == 8.0
    b = back[(back["run_id"] == "id-loss/011") & (back["metric"] == "psnr")].iloc[0]
    assert b["axis.gaussiands.losses.depth"] == False and b["axis.gaussiands.losses.ds"] == True  # noqa: E712
    lp = back[(back["run_id"] == "id-main/vanilla_bench") & (back["metric"] == "lpips")].iloc[0]
    assert math.isnan(lp["value"]) and lp["reason"] == "no LPIPS weights"


def test_bad_results_name_the_file(tmp_path: Path):
    """A bad results.json becomes one failed row whose reason names the file and the problem."""
    root = tmp_path / "runs"
    d = write_run(root, "a", method="gaussiands", scene="bench", metrics={"psnr": 20.0})
    write_run(root, "b", method="vanilla", scene="bench", metrics={"psnr": 21.0})
    res = json.loads((d / "results.json").read_text())

    def reason_of(text: str) -> str:
        (d / "results.json").write_text(text)
        df = collect(root)
        bad = df[df["run_dir"] == str(d)]
        assert len(bad) == 1 and bad.iloc[0]["status"] == "failed" and math.isnan(bad.iloc[0]["value"])
        assert len(df.attrs["unreadable"]) == 1 and df[df["metric"] == "psnr"]["value"].tolist() == [21.0]
        return bad.iloc[0]["reason"]

    del res["scene"]
    assert "a/results.json: missing key 'scene'" in reason_of(json.dumps(res))
    res["scene"] = "bench"
    res["metrics"]["psnr"] = "high"
    assert "results.json: metrics.psnr must be a number" in reason_of(json.dumps(res))
    assert "a/results.json: corrupt or truncated JSON" in reason_of('{"run_id": "x", ')
    (root / "b" / "results.json").write_text("{")              # nothing readable at all: an error
    with pytest.raises(InputError, match=r"no results.json could be read: .*corrupt or truncated JSON.* 1 more"):
        collect(root)


def test_empty_dir_duplicates_and_hidden(tmp_path: Path):
    root = tmp_path / "runs"
    root.mkdir()
    with pytest.raises(InputError, match="no results.json found"):
        collect(root)
    write_run(root, "a", method="vanilla", scene="s", metrics={"psnr": 20.0})
    write_run(root, "copy_of_a", method="vanilla", scene="s", metrics={"psnr": 20.0})
    res = json.loads((root / "copy_of_a" / "results.json").read_text())
    res["run_id"] = "id-a"
    (root / "copy_of_a" / "results.json").write_text(json.dumps(res))
    write_run(root, ".cache/x", method="vanilla", scene="s", metrics={"psnr": 1.0})
    df = collect(root)
    assert df["run_id"].nunique() == 1 and len(df[df["metric"] == "psnr"]) == 1
    assert len(df.attrs["warnings"]) == 1 and "duplicate" in df.attrs["warnings"][0]


def test_missing_reason_is_looked_up_by_metric_name_only():
    """skipped is keyed by metric name: no token or prefix matching of free-text keys."""
    sk = {"lpips": "no LPIPS weights", "miou_3dovs_decode": "no semantic field (decode)",
          "3dovs_encode": "a free-text key", "semantics": "vanilla"}
    assert missing_reason("lpips", sk, "done") == "no LPIPS weights"
    assert missing_reason("miou_3dovs_decode", sk, "done") == "no semantic field (decode)"
    assert missing_reason("miou_3dovs_encode", sk, "done") == "no reason recorded"
    assert missing_reason("miou_lerf", sk, "done") == "no reason recorded"
    assert missing_reason("psnr", {}, "failed") == "run failed"


def test_dropped_column_and_axis_from_resolved_config(tmp_path: Path):
    """Two loss-subset cells on a scene without depth: the grid asked for depth on and off, the
    resolver switched it off in both, so axis.<key> (resolved) agrees and `dropped` says why."""
    root = tmp_path / "runs"
    why = "no depth prior: scene has no depth"
    for name, asked in (("on", True), ("off", False)):
        write_run(root, f"ls/{name}", method="gaussiands", scene="s", study="loss_subsets",
                  grid={"gaussiands.losses.depth": asked}, metrics={"psnr": 20.0},
                  config_extra={"gaussiands": {"losses": {"depth": False}}})
        res_path = root / "ls" / name / "results.json"
        res = json.loads(res_path.read_text())
        res["dropped"] = {"gaussiands.losses.depth": why, "priors.depth": why} if asked else {"priors.depth": why}
        res_path.write_text(json.dumps(res))
    df = collect(root)
    on = df[(df["run_id"] == "id-ls/on") & (df["metric"] == "psnr")].iloc[0]
    off = df[(df["run_id"] == "id-ls/off") & (df["metric"] == "psnr")].iloc[0]
    assert on["axis.gaussiands.losses.depth"] == off["axis.gaussiands.losses.depth"]
    assert not on["axis.gaussiands.losses.depth"]
    assert on["requested.gaussiands.losses.depth"] == "True" and off["requested.gaussiands.losses.depth"] == "False"
    assert on["dropped"] == f"gaussiands.losses.depth: {why}; priors.depth: {why}"
    assert off["dropped"] == f"priors.depth: {why}"
    plain = df[(df["metric"] == "psnr")]
    assert "dropped" in BASE_COLUMNS and set(plain["dropped"]) >= {off["dropped"]}


def test_cli_collect(runs: Path, capsys):
    assert main(["collect", str(runs)]) == 0
    out = capsys.readouterr().out
    assert "collected 28 runs" in out and "collected.parquet" in out and "standalone" in out
    assert (runs / "collected.parquet").exists()
    empty = runs.parent / "empty"
    empty.mkdir()
    assert main(["collect", str(empty)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no results.json found" in err


def test_descriptive_timings_are_not_rows(tmp_path: Path):
    write_run(tmp_path, "a", method="vanilla", scene="s", metrics={"psnr": 20.0, "fps": 2.0},
              timings={"train_s": 5.0, "fps": 2.0, "fps_sync": "none (cpu, synchronous)"})
    df = collect(tmp_path)
    assert sorted(df["metric"]) == ["fps", "peak_rss_mb", "psnr", "train_s"]
    assert df[df["metric"] == "fps"].iloc[0]["source"] == "metrics"
