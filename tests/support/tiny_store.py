"""What the store tests share: the tiny plan's grid (two vanilla cells of 3 steps on the tiny scene) and a
hand-made published record."""
from __future__ import annotations

TINY_GRID = {"study": "tiny-test",
             "base": {"method": "vanilla", "preset": "cpu-small",
                      "set": {"train.iterations": 3, "train.max_width": 32, "train.eval_every": 0,
                              "eval.previews": 0, "eval.fps_warmup": 0, "eval.fps_repeats": 1}},
             "scenes": [{"preset": "tabletop-small", "views": 8, "resolution": [32, 24]}], "seeds": [0],
             "axes": {"train.lambda_dssim": [0.2, 0.0]}}


def hand_record(run_id: str, psnr: float, lr: float = 0.01, store_version: int = 1) -> dict:
    """A published cell of grid `g` as a store of `store_version` holds it (before its shared parts)."""
    return {"store_version": store_version, "numerics_version": 1, "grid": "g", "study": "s", "run_id": run_id,
            "cell": {"method": "vanilla", "seed": 0, "scene": {"preset": "p"}, "axes": {}},
            "scene_fingerprint": "fp",
            "config": {"run_id": run_id, "train": {"iterations": 100, "lr": {"color": lr}}, "eval": {"previews": 2}},
            "results": {"run_id": run_id, "metrics": {"psnr": psnr}, "metric_impl": {"psnr": "psnr/v1"},
                        "frames": {"test": ["a.png", "b.png"]}, "per_view": {"psnr": [psnr, psnr]}},
            "train_summary": {"status": "done"}, "provenance": {"gsbench_commit": "abc"}}
