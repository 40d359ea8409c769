"""benchmarks/versus.py: its table parsing and ratios (the end-to-end run installs two commits and is
left to the benchmark itself; nothing here times anything)."""
from bench_scripts import load_benchmark


def test_rows_skip_separators_and_split_cells():
    mod = load_benchmark("versus")
    md = "| a | b |\n|---|---|\n| cpu | 2.0 |\nnot a row\n| x | y |"
    assert mod._rows(md) == [["a", "b"], ["cpu", "2.0"], ["x", "y"]]


def test_table_ratios_point_the_right_way():
    mod = load_benchmark("versus")
    base = {"side": "old", "load": 0.1, "render_fwdbwd_ms": 100.0, "gaussiands_its": 4.0,
            "train_s": 80.0, "eval_s": 20.0, "psnr": 25.0, "miou_3dovs": 0.5, "miou_lerf": 0.6}
    head = {"side": "new", "load": 0.2, "render_fwdbwd_ms": 40.0, "gaussiands_its": 6.0,
            "train_s": 30.0, "eval_s": 10.0, "psnr": 25.1, "miou_3dovs": 0.51, "miou_lerf": 0.59}
    t = mod.table(base, head)
    assert "| cpu render fwd+bwd ms | 100.00 | 40.00 | 2.50x |" in t          # time: old / new
    assert "| gaussiands it/s | 4.00 | 6.00 | 1.50x |" in t                  # rate: new / old
    assert "| cpu-medium train+eval s | 100.0 | 40.0 | 2.50x |" in t
    assert "| psnr | 25.0000 | 25.1000 | |" in t
    assert "bare step" not in t                                             # absent on both sides: no row


def test_raster_scene_saves_a_field_and_times_it(tmp_path):
    """raster_scene.py: --make writes train_speed's initial field and cameras, --time renders them
    (forward and forward+backward) and reports positive times; versus.py times both sides with it."""
    import json

    mod = load_benchmark("raster_scene")
    f = tmp_path / "field.pt"
    assert mod.main(["--make", str(f), "--size", "300@32x24"]) == 0
    import torch
    d = torch.load(f, weights_only=False)
    assert d["field"]["means"].shape == (300, 3) and d["field"]["features"].shape == (300, 3)
    assert len(d["cameras"]) == 3 and all(c[2:] == (32, 24) for c in d["cameras"])
    r = mod.time_file(f, repeats=1)
    assert r["fwd_ms"] > 0 and r["fwdbwd_ms"] > 0 and r["size"] == "300@32x24"
    json.dumps(r)
