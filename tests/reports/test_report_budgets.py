"""Report parts read beside the collected metrics: each method's training budget (results budget or
resolved config), the loss-share plot from train_log.jsonl, and the list of dropped settings."""
from __future__ import annotations

import json
from pathlib import Path

from PIL import Image
from report_runs import write_run

from gsbench.collect import collect
from gsbench.config import load_config
from gsbench.reports.budgets import budget_table
from gsbench.reports.data import Results
from gsbench.reports.shares import mean_shares, read_shares


def _config(method: str, *sets: str) -> dict:
    """A whole resolved-looking config, as a run's results.json records it (the budget rules read it)."""
    return load_config(method, None, ["train.iterations=500", *sets])


def _budget_runs(root: Path) -> None:
    write_run(root, "v", method="vanilla", scene="s", config_extra=_config("vanilla"))
    write_run(root, "t", method="twostage", scene="s",
              config_extra=_config("twostage", "twostage.semantic_iterations=150"))
    g = write_run(root, "g", method="gaussiands", scene="s", config_extra=_config("gaussiands"))
    g2 = write_run(root, "g2", method="gaussiands", scene="s", seed=1, config_extra=_config("gaussiands"))
    for run in (g2,):  # a results budget wins over the config
        res = json.loads((run / "results.json").read_text())
        res["budget"] = {"iterations": 400, "semantic_iterations": 300}
        (run / "results.json").write_text(json.dumps(res))
    assert g.exists()


def test_budget_table(tmp_path: Path):
    _budget_runs(tmp_path)
    (t,) = budget_table(Results(collect(tmp_path)))
    got = [(r.labels, [c.plain() for c in r.cells]) for r in t.rows]
    assert got == [
        (["(standalone)", "3DGS (vanilla)"], ["500", "– (no semantic field)", "resolved config", "1"]),
        (["(standalone)", "Two-stage"], ["500", "150", "resolved config", "1"]),
        (["(standalone)", "GaussianDS"], ["500", "500 (joint)", "resolved config", "1"]),
        (["(standalone)", "GaussianDS"], ["400", "300", "results budget", "1"]),
    ]


def test_budget_unknown_without_run_folder(tmp_path: Path):
    _budget_runs(tmp_path)
    df = collect(tmp_path)
    df["run_dir"] = str(tmp_path / "gone")
    (t,) = budget_table(Results(df))
    assert {r.cells[2].plain() for r in t.rows} == {"unknown (results.json not readable)"}


def _log(run: Path, lines: list[dict]) -> None:
    (run / "train_log.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))


def test_loss_shares_read_and_averaged(tmp_path: Path):
    run = tmp_path / "r"
    run.mkdir()
    _log(run, [{"step": 10, "loss_share": {"rgb": 0.9, "depth": 0.1}},
               {"step": 20, "loss_share": {"rgb": 0.8, "depth": 0.2}},
               {"step": 30, "loss": {"total": 1.0}},  # no share: ignored
               {"step": 40, "loss_share": {"rgb": "x", "depth": float("nan")}}])  # nothing valid: ignored
    got = read_shares(str(run))
    assert got == {10: {"rgb": 0.9, "depth": 0.1}, 20: {"rgb": 0.8, "depth": 0.2}}
    steps, mean = mean_shares([got, {10: {"rgb": 0.7, "sem": 0.3}, 20: {"rgb": 1.0}}])
    assert steps == [10, 20]
    assert mean["rgb"] == [0.8, 0.9] and mean["depth"] == [0.05, 0.1] and mean["sem"] == [0.15, 0.0]


def test_report_plots_shares_and_lists_dropped(tmp_path: Path):
    runs = tmp_path / "runs"
    for s in (0, 1):
        r = write_run(runs, f"g{s}", method="gaussiands", scene="s", seed=s, metrics={"psnr": 20.0 + s},
                      config_extra={"train": {"iterations": 500}})
        _log(r, [{"step": k, "wall_s": k / 10, "loss_share": {"rgb": 1 - k / 1000, "depth": k / 1000}}
                 for k in (100, 200, 300)])
    write_run(runs, "v", method="vanilla", scene="s", metrics={"psnr": 19.0})  # logs no shares
    from gsbench.reports.build import build_report
    s = build_report(runs, tmp_path / "rep")
    png = tmp_path / "rep" / "plots" / "shares_main.png"
    assert png in s.plots and Image.open(png).size[0] > 100
    html = (tmp_path / "rep" / "index.html").read_text()
    assert "plots/shares_main.png" in html and "1 of 3 run(s) log no loss_share" in html
    assert "Training budget per method" in html
    assert "The resolver dropped no setting in any run." in html   # collect carries the `dropped` column


def test_report_prints_requested_tables(tmp_path: Path, capsys):
    from gsbench.cli import main
    _budget_runs(tmp_path / "runs")
    assert main(["report", str(tmp_path / "runs"), "--out", str(tmp_path / "rep"), "--no-progress",
                 "--print", "budgets"]) == 0
    out = capsys.readouterr().out
    assert "### Training budget per method" in out and "| (standalone) | Two-stage | 500 | 150 |" in out
    assert main(["report", str(tmp_path / "runs"), "--out", str(tmp_path / "rep"), "--no-progress",
                 "--print", "paper_claims"]) == 1  # no ablation ran: no claims table
    err = capsys.readouterr().err
    assert "no table paper_claims" in err and "(tables: budgets)" in err


def test_budget_reads_the_methods_record_and_null_semantic_iterations(tmp_path: Path):
    """results.json `budget` as the methods record it ({rgb_steps, semantic_steps}) wins over the config;
    a twostage config with semantic_iterations null means train.iterations semantic steps."""
    t = write_run(tmp_path, "t", method="twostage", scene="s", config_extra=_config("twostage"))
    t2 = write_run(tmp_path, "t2", method="twostage", scene="s", seed=1, config_extra=_config("twostage"))
    res = json.loads((t2 / "results.json").read_text())
    res["budget"] = {"rgb_steps": 300, "semantic_steps": 200}
    (t2 / "results.json").write_text(json.dumps(res))
    assert t.exists()
    (tab,) = budget_table(Results(collect(tmp_path)))
    got = sorted([c.plain() for c in r.cells] for r in tab.rows)
    assert got == [["300", "200", "results budget", "1"], ["500", "500", "resolved config", "1"]]
