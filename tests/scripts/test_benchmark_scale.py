"""benchmarks/scale.py runs end to end at a tiny size (a smoke test: every phase reported, the
requested Gaussians trained, the cache read back; no timing or memory figure asserted)."""
import json

from bench_scripts import load_benchmark


def test_scale_rehearsal_runs_every_phase_at_a_tiny_size(tmp_path, capsys):
    mod = load_benchmark("scale")
    out_json = tmp_path / "r.json"
    assert mod.main(["--views", "9", "--size", "48x36", "--gaussians", "400", "--steps", "2",
                     "--work", str(tmp_path / "w"), "--json", str(out_json)]) == 0
    out = capsys.readouterr().out
    r = json.loads(out_json.read_text())
    assert [p["phase"] for p in r["phases"]] == ["generate", "load scene", "load images", "priors", "cache",
                                                 "train", "eval"]
    assert r["gaussians"] == 400 and r["train_size"] == [48, 36]
    cache = next(p for p in r["phases"] if p["phase"] == "cache")
    assert "'depth': True, 'masks': True, 'mask-stats': True, 'features': True" in cache["note"]
    assert all(p["peak_rss_mb"] > 0 and p["wall_s"] >= 0 for p in r["phases"])
    assert "| eval |" in out and "psnr" in next(p for p in r["phases"] if p["phase"] == "eval")["note"]
