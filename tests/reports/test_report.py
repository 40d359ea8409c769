"""gsbench report from hand-written results.json files (no training): table values and bold marks
(expected values computed by hand from the synthetic inputs), plots are valid PNGs, the HTML
references them and carries provenance; partial run folders; protocol separation."""
from __future__ import annotations

import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from report_runs import LAMBDA_DEPTH, LAMBDA_SEM, lambda_miou, make_all, make_main, write_run

from gsbench.cli import main
from gsbench.collect import collect, read_collected, write_collected
from gsbench.reports.build import build_tables
from gsbench.reports.data import Results
from gsbench.reports.plots import pareto_front, train_curve
from gsbench.reports.stats import pearson
from gsbench.reports.studies import reconstruction_table
from gsbench.reports.table import Cell, Column, Row, Table


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("rep")
    make_all(root / "runs")
    assert main(["report", str(root / "runs"), "--out", str(root / "report"), "--no-progress"]) == 0
    return root / "report"


def md_rows(report: Path, table_id: str) -> list[list[str]]:
    """Body rows of a Markdown table file as lists of cell strings (header and rule skipped)."""
    lines = [ln for ln in (report / "tables" / f"{table_id}.md").read_text().splitlines() if ln.startswith("|")]
    return [[c.strip() for c in re.split(r"(?<!\\)\|", ln)[1:-1]] for ln in lines[2:]]


def row_of(rows: list[list[str]], label: str) -> list[str]:
    hits = [r for r in rows if r[0] == label]
    assert len(hits) == 1, (label, rows)
    return hits[0]


# ---------------------------------------------------------------------------- tables
def test_reconstruction_table(report: Path):
    rows = md_rows(report, "reconstruction")
    # columns: Scene | vanilla SSIM PSNR LPIPS FPS | twostage x4 | gaussiands x4
    assert rows[0][0] == "*3D-OVS protocol*"
    bench = row_of(rows, "bench")
    assert bench[1:5] == ["0.600", "20.00", "n/a (no LPIPS weights)", "100.0"]
    assert bench[5:9] == ["0.650", "22.00", "n/a (no LPIPS weights)", "**120.0**"]
    # two seeds: mean and sample std by hand: ssim (0.70, 0.72) -> 0.710 +- 0.0141; psnr (24, 26) -> 25 +- 1.414
    assert bench[9:13] == ["**0.710 ± 0.014 (n=2)**", "**25.00 ± 1.41 (n=2)**", "n/a (no LPIPS weights)",
                          "100.0 ± 14.1 (n=2)"]
    sofa = row_of(rows, "sofa")
    assert sofa[1:5] == ["–"] * 4  # no vanilla run on sofa
    assert sofa[5] == "**0.810**" and sofa[10] == "**26.00**" and sofa[6] == "25.00"
    assert "*LERF-OVS protocol*" in [r[0] for r in rows]
    kitchen = row_of(rows, "waldo_kitchen")
    assert kitchen[7] == "0.250" and kitchen[11] == "**0.200**"  # LPIPS: lower is better
    tex = (report / "tables" / "reconstruction.tex").read_text()
    assert "\\textbf{25.00 $\\pm$ 1.41 (n=2)}" in tex and "waldo\\_kitchen" in tex
    assert "\\multicolumn{4}{c|}{\\textit{\\textbf{3DGS (vanilla)}}}" in tex
    assert "\\textbf{0.600}" not in tex


def test_semantic_tables(report: Path):
    rows = md_rows(report, "3dovs_miou_mbiou")
    g = row_of(rows, "GaussianDS")
    # bench (0.90, 0.94) -> 92.00 +- 2.83; sofa 98.00; overall mIoU (92 + 98) / 2 = 95.00
    assert g == [
        "GaussianDS",
        "**92.00 ± 2.83 (n=2)**",
        "**82.00 ± 2.83 (n=2)**",
        "**98.00**",
        "**86.00**",
        "**95.00**",
        "**84.00**",
    ]
    t = row_of(rows, "Two-stage")
    assert t[1:] == ["85.00", "70.00", "80.00", "75.00", "82.50", "72.50"]
    v = row_of(rows, "3DGS (vanilla)")
    assert v[1] == "n/a (method has no semantic field)" and v[3] == "–"
    lerf = md_rows(report, "lerf_miou")
    assert "GaussianDS" not in [r[0] for r in lerf]  # configured mode = the encode row, not repeated
    assert row_of(lerf, "GaussianDS (encode)")[1:] == ["**61.40**", "**61.40**"]
    assert row_of(lerf, "GaussianDS (decode)")[1:] == ["55.00", "55.00"]
    assert row_of(lerf, "Two-stage")[1:] == ["50.00", "50.00"]


def test_ablation_tables(report: Path):
    rows = md_rows(report, "loss_subsets")
    assert len(rows) == 8
    # paper order: none, depth, tv, ds, depth+tv, depth+ds, (tv+ds), all; values 20 + 2d + t + 0.5s
    assert rows[0] == ["", "", "", "20.00", "50.00"]
    assert rows[1] == ["✓", "", "", "22.00", "70.00"]
    assert rows[3] == ["", "", "✓", "20.50", "65.00"]
    assert rows[7] == ["✓", "✓", "✓", "**23.50**", "**95.00**"]
    assert sum(c.count("**") for r in rows for c in r) == 4  # only the best row is bold
    tex = (report / "tables" / "loss_subsets.tex").read_text()
    assert tex.count("\\checkmark") == 12

    form = md_rows(report, "depth_formulation")
    assert [r[0] for r in form] == ["No depth loss", "Raw L1 supervision", "Min-max normalized depth",
                                    "Scale-shift aligned depth", "Pearson correlation"]
    assert row_of(form, "Scale-shift aligned depth")[1:4] == ["0.700", "**24.81**", "**0.184**"]
    assert row_of(form, "Min-max normalized depth")[3] == "**0.184**"  # tie: both bold
    assert all(r[1] == "0.700" for r in form)  # all equal: no bold

    order = md_rows(report, "ordering")
    assert order == [["Random", "5.000", "33.92"], ["Filename order", "2.030", "50.85"],
                     ["Pose-nearest", "**1.500**", "**53.21**"]]

    lat = md_rows(report, "latent_dim_waldo_kitchen")
    head = [
        ln for ln in (report / "tables" / "latent_dim_waldo_kitchen.md").read_text().splitlines() if ln.startswith("|")
    ][0]
    assert [c.strip() for c in head.split("|")[1:-1]] == ["Latent dimension d", "3", "8", "16", "3DGS (vanilla)"]
    assert row_of(lat, "Training time (min)")[1:] == ["2.00", "4.00", "8.00", "**1.00**"]
    assert row_of(lat, "Peak RSS memory (MB)")[1:] == ["500", "600", "800", "**300**"]
    assert row_of(lat, "mIoU (%)")[1:] == ["61.00", "**63.00**", "62.00", "n/a (method has no semantic field)"]
    assert row_of(lat, "PSNR (dB)")[1:] == ["23.60", "**23.70**", "23.65", "22.00"]

    noise = md_rows(report, "depth_noise")
    assert noise[0] == ["clean (no noise)", "0", "**25.00**", "**0.800**", "**95.00**"]
    assert ["Motion blur", "3", "22.00", "0.770", "89.00"] in noise
    assert noise[-1] == ["Salt-and-pepper", "5", "n/a (run failed)", "n/a (run failed)", "n/a (run failed)"]


def test_lambda_pearson(report: Path):
    rows = md_rows(report, "lambda_pearson")
    xs, ys_m, ys_p = [], [], []
    for ld in LAMBDA_DEPTH:
        for ls in LAMBDA_SEM:
            xs.append((ld, ls))
            ys_m.append(lambda_miou(ld, ls))
            ys_p.append(24.0 - 10 * ld)
    r_depth = np.corrcoef([x[0] for x in xs], ys_m)[0, 1]  # independent reference
    r_sem = np.corrcoef([x[1] for x in xs], ys_m)[0, 1]
    assert row_of(rows, "λ_depth")[2].startswith(f"{r_depth:.3f} [")
    assert row_of(rows, "λ_sem")[2].startswith(f"{r_sem:.3f} [")
    n = len(xs)
    lo, hi = np.tanh(np.arctanh(r_sem) + np.array([-1.96, 1.96]) / np.sqrt(n - 3))  # Fisher z, by hand
    assert f"[{lo:.3f}, {hi:.3f}]" in row_of(rows, "λ_sem")[2] and row_of(rows, "λ_sem")[2].endswith(f"(n={n})")
    assert row_of(rows, "λ_depth")[3].startswith("-1.000 [")  # PSNR is linear, decreasing in lambda_depth


# ---------------------------------------------------------------------------- plots and HTML
def _valid_png(p: Path) -> tuple[int, int]:
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", p
    with Image.open(p) as im:
        im.verify()
    with Image.open(p) as im:
        arr = np.asarray(im.convert("L"), dtype=np.float64)
    assert arr.std() > 5.0, f"{p} looks blank"
    return im.size


def test_plots_exist_and_are_png(report: Path):
    pngs = sorted((report / "plots").glob("*.png"))
    names = {p.name for p in pngs}
    expected = {"time_main.png", "time_loss_subsets.png", "time_depth_formulation.png", "time_ordering.png",
                "time_latent_dim.png", "time_lambda_grid.png", "time_depth_noise.png",
                "lambda_surfaces_bench.png", "noise_bench.png", "latent_dim_waldo_kitchen.png",
                "bars_reconstruction.png", "bars_3dovs_miou_mbiou.png", "bars_lerf_miou.png", "bars_loss_subsets.png",
                "bars_ordering.png", "bars_depth_formulation.png", "bars_depth_noise.png"}
    assert expected <= names, expected - names
    for p in pngs:
        w, h = _valid_png(p)
        assert w > 200 and h > 200


def test_html_references_plots_tables_and_provenance(report: Path):
    html = (report / "index.html").read_text()
    srcs = re.findall(r'<img src="([^"]+)"', html)
    assert sorted(srcs) == sorted(f"plots/{p.name}" for p in (report / "plots").glob("*.png"))
    for s in srcs:
        assert (report / s).is_file()
    assert "<strong>25.00 ± 1.41 (n=2)</strong>" in html and "n/a (no LPIPS weights)" in html
    for t in ("reconstruction", "3dovs_miou_mbiou", "loss_subsets", "latent_dim_waldo_kitchen", "depth_noise"):
        assert f'id="tab-{t}"' in html
    prov = html[html.index('id="provenance"'):]
    for needle in ("simulated-flow", "text-aligned", "torch", "3dovs", "lerf", "gsbench.ssim.gauss11.zero-pad.v1",
                   "lpips.vgg.v0.1", "testhost", "Test CPU", "abc1234"):
        assert needle in prov, needle
    assert "No runs for" not in html  # every study is present
    for f in ("tables.md", "tables.tex", "collected.parquet"):
        assert f'href="{f}"' in html and (report / f).is_file()


def test_partial_runs_dir(tmp_path: Path):
    root = tmp_path / "runs"
    write_run(root, "o/random", method="gaussiands", scene="bench", study="ordering",
              grid={"priors.ordering": "random"},
              metrics={"ordering_adjacent_distance": 4.0, "ordering_adjacent_mask_iou_strict": 0.25})
    write_run(root, "o/pose", method="gaussiands", scene="bench", study="ordering", grid={"priors.ordering": "pose"},
              metrics={"ordering_adjacent_distance": 1.0, "ordering_adjacent_mask_iou_strict": 0.5})
    out = tmp_path / "rep"
    from gsbench.reports import build_report
    s = build_report(root, out)
    assert s.tables == ["ordering", "ordering_diff", "paper_claims", "budgets"]
    html = (out / "index.html").read_text()
    note = re.search(r"No runs for: ([^<]*)", html).group(1)
    for st in ("main results", "depth_formulation", "loss_subsets", "latent_dim", "lambda_grid", "depth_noise"):
        assert st in note
    assert "ordering" not in note.replace("main results", "")
    assert md_rows(out, "ordering") == [["Random", "4.000", "25.00"], ["Pose-nearest", "**1.000**", "**50.00**"]]
    # one seed per row: a difference, but its interval is n/a, never of zero width
    assert md_rows(out, "ordering_diff") == [
        ["Random", "+3.000 [n/a: one seed] (n=1, paired)", "-25.00 [n/a: one seed] (n=1, paired)"],
        ["Pose-nearest", "reference", "reference"]]
    assert not (out / "tables" / "reconstruction.md").exists()


def test_report_cli_errors(tmp_path: Path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(["report", str(tmp_path / "empty"), "--out", str(tmp_path / "r"), "--no-progress"]) == 1
    assert "no results.json found" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "missing"), "--out", str(tmp_path / "r")]) == 1


# ---------------------------------------------------------------------------- units (fast)
def test_protocols_never_averaged(tmp_path: Path):
    root = tmp_path / "runs"
    write_run(root, "a", method="gaussiands", scene="bench", seed=0, protocol="3dovs", metrics={"psnr": 20.0})
    write_run(root, "b", method="gaussiands", scene="bench", seed=1, protocol="lerf", metrics={"psnr": 30.0})
    write_run(root, "c", method="gaussiands", scene="bench", seed=2, protocol="lerf", metrics={"psnr": 28.0})
    (t,) = reconstruction_table(Results(collect(root)))
    psnr = t.columns.index(next(c for c in t.columns if c.metric == "psnr"))
    got = [(r.section, r.labels[0], r.cells[psnr].plain()) for r in t.rows]
    assert got == [("3D-OVS protocol", "bench", "20.00"), ("LERF-OVS protocol", "bench", "29.00 ± 1.41 (n=2)")]


def test_partial_seeds_and_mixed_configs(tmp_path: Path):
    root = tmp_path / "runs"
    write_run(root, "a", method="vanilla", scene="s", seed=0, metrics={"psnr": 20.0})
    write_run(root, "b", method="vanilla", scene="s", seed=1, metrics={"psnr": None}, status="nonfinite")
    write_run(root, "c", method="vanilla", scene="s", seed=2, metrics={"psnr": 22.0}, config_extra={"train": {"it": 5}})
    (t,) = reconstruction_table(Results(collect(root)))
    psnr = next(j for j, c in enumerate(t.columns) if c.metric == "psnr")
    assert t.rows[0].cells[psnr].plain() == "21.00 ± 1.41 (n=2/3)"
    assert any("differ by more than the seed" in n and "s/vanilla" in n for n in t.notes)


def test_collected_file_gives_same_tables(tmp_path: Path):
    root = tmp_path / "runs"
    make_main(root)
    df = collect(root)
    path = write_collected(df, root)
    a = [t.to_markdown() for t in build_tables(Results(df))]
    b = [t.to_markdown() for t in build_tables(Results(read_collected(path)))]
    assert a == b and len(a) == 4  # with the budget table


def test_cell_format_and_bold_rules():
    assert Cell(mean=1.23456, decimals=2, n=1, total=1).plain() == "1.23"
    assert Cell(mean=1.0, std=0.5, n=3, total=3, decimals=1).plain() == "1.0 ± 0.5 (n=3)"
    assert Cell(reason="no LPIPS weights").plain() == "n/a (no LPIPS weights)"
    assert Cell().plain() == "–"
    cols = [Column("psnr", "PSNR", "PSNR", "higher"), Column("lpips", "LPIPS", "LPIPS", "lower")]
    rows = [Row(["a_1"], [Cell(mean=20.004, n=1), Cell(mean=0.3, n=1)]),
            Row(["b|2"], [Cell(mean=19.996, n=1), Cell(reason="x", n=0)]),
            Row(["c"], [Cell(mean=10.0, n=1), Cell(mean=0.4, n=1)])]
    t = Table("t", "T", "cap 50%", ["Name"], cols, rows)
    t.bold_best_per_column()
    md = t.to_markdown()
    assert "| a_1 | **20.00** | **0.30** |" in md  # 20.004 and 19.996 round to the same shown value: both bold
    assert "| b\\|2 | **20.00** | n/a (x) |" in md
    assert "| c | 10.00 | 0.40 |" in md
    tex = t.to_latex()
    assert "a\\_1 & \\textbf{20.00} & \\textbf{0.30}" in tex and "cap 50\\%" in tex


def test_pareto_pearson_and_train_curve(tmp_path: Path):
    pts = [(10.0, 20.0), (20.0, 25.0), (15.0, 19.0), (30.0, 25.0), (5.0, 10.0)]
    assert pareto_front(pts) == [4, 0, 1]  # (5,10) (10,20) (20,25); (30,25) dominated by (20,25)
    r, why = pearson([1, 2, 3], [2, 4, 7])
    assert why is None and r == pytest.approx(5 / math.sqrt(2 * (76 / 6)), abs=1e-12)  # hand: Sxy=5, Sxx=2, Syy=38/3
    assert pearson([1, 1, 1], [1, 2, 3]) == (None, "lambda constant")
    assert pearson([1, 2], [1, 2])[0] is None
    d = write_run(tmp_path, "r", method="twostage", scene="s", metrics={"psnr": 1.0},
                  curve=[(1.0, {"psnr": 10.0}), (2.0, {"psnr": 12.0})])
    xs, ys = train_curve(str(d), ["psnr"])
    assert xs == [1.0, 2.0] and ys == [10.0, 12.0]  # torn last line ignored
    # a second phase restarts its clock: laid after the first
    with open(d / "train_log.jsonl", "w") as f:
        f.write('{"phase": "rgb", "step": 1, "wall_s": 3.0, "eval": {"psnr": 5.0}}\n')
        f.write('{"phase": "rgb", "step": 2, "wall_s": 4.0}\n')
        f.write('{"phase": "semantic", "step": 1, "wall_s": 1.5, "eval": {"psnr": 6.0}}\n')
    assert train_curve(str(d), ["psnr"]) == ([3.0, 5.5], [5.0, 6.0])


def test_lambda_slice_keeps_one_sweep(tmp_path: Path):
    """Two sweeps (depth x sem, tv x ds) around defaults: the depth x sem surface uses only the runs
    with tv and ds at their default (the most common value), never runs of the other sweep."""
    from gsbench.reports.display import AX_LAMBDAS
    from gsbench.reports.plots import _lambda_slice
    root = tmp_path / "runs"
    cells = {(d, 1.5, s, 1.0) for d in (0.001, 0.01, 0.1) for s in (1.0, 5.0)}
    cells |= {(0.01, t, 5.0, ds) for t in (0.5, 3.0) for ds in (0.25, 2.0)}
    for i, (d, t, s, ds) in enumerate(sorted(cells)):
        write_run(root, f"c{i}", method="gaussiands", scene="b", study="lambda_grid",
                  grid={"gaussiands.lambdas.depth": d, "gaussiands.lambdas.tv": t,
                        "gaussiands.lambdas.sem": s, "gaussiands.lambdas.ds": ds}, metrics={"miou_3dovs": 0.5})
    res = Results(collect(root))
    ids = res.run_ids(study="lambda_grid")
    sl = _lambda_slice(res, ids, AX_LAMBDAS, AX_LAMBDAS[::2])  # keep depth and sem
    assert len(ids) == 10 and len(sl) == 6
    assert all(res.runs.at[r, "axis.gaussiands.lambdas.tv"] == 1.5 for r in sl)


def test_long_reason_is_shortened_in_cells(tmp_path: Path):
    long = "no LPIPS weights: backbone vgg16.pth not found (set GSBENCH_WEIGHTS)"
    write_run(
        tmp_path, "a", method="vanilla", scene="s", metrics={"psnr": 20.0, "lpips": None}, skipped={"lpips": long}
    )
    res = Results(collect(tmp_path))
    (t,) = reconstruction_table(res)
    lp = next(j for j, c in enumerate(t.columns) if c.metric == "lpips")
    assert t.rows[0].cells[lp].plain() == "n/a (no LPIPS weights)"
    assert res.long_reasons == {"no LPIPS weights": {long}}


def test_rerun_removes_stale_outputs(tmp_path: Path):
    """A re-run replaces the report it wrote: the tables and figures of a study that is gone go too."""
    from gsbench.reports import build_report
    root = tmp_path / "runs"
    write_run(root, "a", method="vanilla", scene="s", metrics={"psnr": 20.0, "ssim": 0.5})
    write_run(root, "o/random", method="gaussiands", scene="s", study="ordering", grid={"priors.ordering": "random"},
              metrics={"ordering_adjacent_distance": 4.0})
    out = tmp_path / "rep"
    build_report(root, out)
    assert (out / "tables" / "ordering.md").is_file() and (out / "plots" / "bars_ordering.png").is_file()
    shutil.rmtree(root / "o")
    s = build_report(root, out)
    assert not (out / "tables" / "ordering.md").exists() and not (out / "plots" / "bars_ordering.png").exists()
    assert sorted(p.name for p in (out / "plots").glob("*.png")) == sorted(p.name for p in s.plots)


def test_unknown_study_gets_generic_table(tmp_path: Path):
    root = tmp_path / "runs"
    for d in (3, 6):
        for ds in (True, False):
            write_run(root, f"t/{d}{ds}", method="gaussiands", scene="tabletop", study="tiny-test",
                      grid={"semantic.latent_dim": d, "gaussiands.losses.ds": ds},
                      metrics={"psnr": 20.0 + d + ds, "miou_3dovs": 0.1 * d})
    tables = build_tables(Results(collect(root)))
    assert [t.id for t in tables] == ["study_tiny_test", "study_tiny_test_diff", "budgets"]
    t = tables[0]
    assert t.label_headers == ["gaussiands.losses.ds", "semantic.latent_dim"] and t.section == "other_tiny-test"
    got = [(r.labels, [c.plain() for c in r.cells]) for r in t.rows]
    assert got == [(["False", "3"], ["23.00", "30.00"]), (["False", "6"], ["26.00", "60.00"]),
                   (["True", "3"], ["24.00", "30.00"]), (["True", "6"], ["27.00", "60.00"])]
    diff = tables[1]  # reference: d = 3 with L_ds on
    assert diff.section == "other_tiny-test"
    assert [r.cells[0].plain() for r in diff.rows] == [
        "-1.00 [n/a: one seed] (n=1, paired)", "+2.00 [n/a: one seed] (n=1, paired)", "reference",
        "+3.00 [n/a: one seed] (n=1, paired)"]


def test_runs_that_differ_only_by_preset_get_distinct_legend_labels(tmp_path: Path):
    from gsbench.reports.run_names import run_labels
    root = tmp_path / "runs"
    for name in ("vanilla_cpu-small", "vanilla_cpu-medium"):
        write_run(root, name, method="vanilla", scene="dtu", metrics={"psnr": 20.0})
    write_run(root, "other", method="gaussiands", scene="dtu", metrics={"psnr": 21.0})
    res = Results(collect(root))
    labels = run_labels(res, list(res.runs.index))
    assert len(set(labels.values())) == 3
    tagged = sorted(v for v in labels.values() if "[" in v)
    assert len(tagged) == 2 and tagged[0].endswith("[vanilla_cpu-medium]") and tagged[1].endswith("[vanilla_cpu-small]")
    assert not any("[" in v for rid, v in labels.items() if res.runs.at[rid, "method"] == "gaussiands")
