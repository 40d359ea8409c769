"""Hand-written results.json / train_log.jsonl files for the collect and report tests (no training).

Values are chosen so that every expected table cell can be computed by hand in the tests.
"""
from __future__ import annotations

import itertools
import json
from pathlib import Path
from typing import Any

MACHINE = {
    "host": "testhost",
    "cpu": "Test CPU",
    "cores": 2,
    "torch": "2.13.0",
    "gsbench": "0.1.0",
    "git_sha": "abc1234",
}
IMPL = {"psnr": "gsbench.psnr.uint8.v1", "ssim": "gsbench.ssim.gauss11.zero-pad.v1", "lpips": "lpips.vgg.v0.1",
        "fps": "gsbench.fps.median.v1", "miou_3dovs": "gsbench.3dovs.argmax.v1", "mbiou_3dovs": "gsbench.biou.v1",
        "miou_lerf": "gsbench.lerf.langsplat.v1"}


def write_run(root: Path, name: str, *, method: str, scene: str, seed: int = 0, study: str | None = None,
              grid: dict | None = None, protocol: str | None = "3dovs", metrics: dict | None = None,
              skipped: dict | None = None, timings: dict | None = None, memory: dict | None = None,
              status: str = "done", curve: list[tuple[float, dict]] | None = None,
              providers: dict | None = None, config_extra: dict | None = None) -> Path:
    run_dir = root / name
    run_dir.mkdir(parents=True, exist_ok=True)
    config = {"method": method, "seed": seed, "grid": grid or {}, **(config_extra or {})}
    res: dict[str, Any] = {
        "run_id": f"id-{name}", "method": method, "scene": scene, "scene_path": f"/data/{scene}", "seed": seed,
        "study": study, "grid": grid or {}, "config": config,
        "providers": providers or {"depth": "gt", "masks": "simulated-flow", "features": "text-aligned"},
        "backend": "torch", "protocol": protocol,
        "metric_impl": {k: v for k, v in IMPL.items() if k in (metrics or {})},
        "metrics": metrics or {}, "per_view": {}, "view_names": [],
        "skipped": skipped or {}, "timings": timings or {"train_s": 100.0, "eval_s": 5.0},
        "memory": memory or {"peak_rss_mb": 400.0}, "machine": MACHINE, "status": status, "dropped": {},
    }
    (run_dir / "results.json").write_text(json.dumps(res, indent=1))
    if curve:
        with open(run_dir / "train_log.jsonl", "w") as f:
            for wall, ev in curve:
                f.write(json.dumps({"step": int(wall * 10), "wall_s": wall, "loss": {"total": 0.1}}) + "\n")
                f.write(json.dumps({"step": int(wall * 10), "wall_s": wall, "loss": {"total": 0.1}, "eval": ev}) + "\n")
            f.write('{"step": 99')  # torn last line: must be ignored
    return run_dir


NO_LPIPS = {"lpips": "no LPIPS weights"}
# skipped is keyed by metric name (gsbench.results)
NO_SEM = "method has no semantic field"


def make_main(root: Path) -> None:
    """Standalone runs on bench, sofa (3D-OVS) and waldo_kitchen (LERF)."""
    c = [(10.0, {"psnr": 15.0, "miou_3dovs": 0.5}), (50.0, {"psnr": 20.0, "miou_3dovs": 0.8})]
    write_run(root, "main/vanilla_bench", method="vanilla", scene="bench",
              metrics={"psnr": 20.0, "ssim": 0.60, "lpips": None, "fps": 100.0, "miou_3dovs": None},
              skipped={**NO_LPIPS, "miou_3dovs": NO_SEM}, curve=c,
              timings={"train_s": 60.0})
    for seed, (p, s, f, mi, mb) in enumerate([(24.0, 0.70, 90.0, 0.90, 0.80), (26.0, 0.72, 110.0, 0.94, 0.84)]):
        write_run(
            root,
            f"main/gds_bench_s{seed}",
            method="gaussiands",
            scene="bench",
            seed=seed,
            metrics={"psnr": p, "ssim": s, "lpips": None, "fps": f, "miou_3dovs": mi, "mbiou_3dovs": mb},
            skipped=NO_LPIPS,
            curve=[(10.0, {"psnr": 16.0, "miou_3dovs": 0.6}), (90.0, {"psnr": p, "miou_3dovs": mi})],
            timings={"train_s": 100.0 + 20 * seed},
        )
    write_run(
        root,
        "main/twostage_bench",
        method="twostage",
        scene="bench",
        metrics={"psnr": 22.0, "ssim": 0.65, "lpips": None, "fps": 120.0, "miou_3dovs": 0.85, "mbiou_3dovs": 0.70},
        skipped=NO_LPIPS,
        curve=c,
        timings={"train_s": 150.0},
    )
    write_run(root, "main/gds_sofa", method="gaussiands", scene="sofa",
              metrics={"psnr": 26.0, "ssim": 0.80, "lpips": None, "fps": 95.0, "miou_3dovs": 0.98, "mbiou_3dovs": 0.86},
              skipped=NO_LPIPS)
    write_run(root, "main/twostage_sofa", method="twostage", scene="sofa",
              metrics={"psnr": 25.0, "ssim": 0.81, "lpips": None, "fps": 97.0, "miou_3dovs": 0.80, "mbiou_3dovs": 0.75},
              skipped=NO_LPIPS)
    write_run(root, "main/gds_kitchen", method="gaussiands", scene="waldo_kitchen", protocol="lerf",
              metrics={"psnr": 23.67, "ssim": 0.87, "lpips": 0.20, "fps": 80.0, "miou_lerf": 0.614,
                       "miou_lerf_encode": 0.614, "miou_lerf_decode": 0.55})
    write_run(root, "main/twostage_kitchen", method="twostage", scene="waldo_kitchen", protocol="lerf",
              metrics={"psnr": 22.5, "ssim": 0.88, "lpips": 0.25, "fps": 85.0, "miou_lerf": 0.50})


def loss_value(depth: bool, tv: bool, ds: bool) -> tuple[float, float]:
    return 20.0 + 2.0 * depth + 1.0 * tv + 0.5 * ds, 0.5 + 0.2 * depth + 0.1 * tv + 0.15 * ds


def make_ablations(root: Path) -> None:
    for d, t, s in itertools.product([False, True], repeat=3):
        p, mi = loss_value(d, t, s)
        write_run(
            root,
            f"loss/{int(d)}{int(t)}{int(s)}",
            method="gaussiands",
            scene="bench",
            study="loss_subsets",
            grid={"gaussiands.losses.depth": d, "gaussiands.losses.tv": t, "gaussiands.losses.ds": s},
            metrics={"psnr": p, "miou_3dovs": mi},
            curve=[(5.0, {"psnr": p - 3, "miou_3dovs": mi - 0.2}), (20.0 + 10 * d, {"psnr": p, "miou_3dovs": mi})],
        )
    forms = {"none": (20.0, 0.300), "raw_l1": (21.31, 0.246), "minmax": (23.93, 0.184),
             "scale_shift": (24.81, 0.184), "pearson": (24.0, 0.190)}
    for f, (p, lp) in forms.items():
        write_run(root, f"form/{f}", method="gaussiands", scene="bench", study="depth_formulation",
                  grid={"gaussiands.depth_formulation": f},
                  metrics={"psnr": p, "lpips": lp, "ssim": 0.7, "miou_3dovs": 0.9, "mbiou_3dovs": 0.8})
    for o, (dist, iou) in {"random": (5.0, 0.3392), "filename": (2.03, 0.5085), "pose": (1.5, 0.5321)}.items():
        write_run(root, f"ord/{o}", method="gaussiands", scene="bench", study="ordering", grid={"priors.ordering": o},
                  metrics={"ordering_adjacent_distance": dist, "ordering_adjacent_mask_iou_strict": iou, "psnr": 24.0})
    lat = {3: (120.0, 500.0, 0.61, 23.6), 8: (240.0, 600.0, 0.63, 23.7), 16: (480.0, 800.0, 0.62, 23.65)}
    for d, (ts, mem, mi, p) in lat.items():
        write_run(root, f"lat/d{d}", method="gaussiands", scene="waldo_kitchen", protocol="lerf", study="latent_dim",
                  grid={"semantic.latent_dim": d}, metrics={"miou_lerf": mi, "psnr": p},
                  timings={"train_s": ts}, memory={"peak_rss_mb": mem})
    write_run(root, "lat/vanilla", method="vanilla", scene="waldo_kitchen", protocol="lerf", study="latent_dim",
              grid={"method": "vanilla"}, metrics={"miou_lerf": None, "psnr": 22.0},
              skipped={"miou_lerf": NO_SEM},
              timings={"train_s": 60.0}, memory={"peak_rss_mb": 300.0})


LAMBDA_DEPTH = [0.001, 0.01, 0.1]
LAMBDA_SEM = [1.0, 5.0]


def lambda_miou(ld: float, ls: float) -> float:
    return 0.5 + 2.0 * ld + 0.05 * ls


def make_lambda_noise(root: Path) -> None:
    for ld, ls in itertools.product(LAMBDA_DEPTH, LAMBDA_SEM):
        write_run(root, f"lam/{ld}_{ls}", method="gaussiands", scene="bench", study="lambda_grid",
                  grid={"gaussiands.lambdas.depth": ld, "gaussiands.lambdas.sem": ls},
                  metrics={"psnr": 24.0 - 10 * ld, "miou_3dovs": lambda_miou(ld, ls)})
    write_run(root, "noise/clean", method="gaussiands", scene="bench", study="depth_noise",
              grid={"priors.depth.noise.type": None, "priors.depth.noise.severity": 0},
              metrics={"psnr": 25.0, "ssim": 0.8, "miou_3dovs": 0.95})
    for kind, drop in {"gaussian": 0.2, "motion_blur": 1.0}.items():
        for sev in (1, 3):
            write_run(
                root,
                f"noise/{kind}_{sev}",
                method="gaussiands",
                scene="bench",
                study="depth_noise",
                grid={"priors.depth.noise.type": kind, "priors.depth.noise.severity": sev},
                metrics={
                    "psnr": 25.0 - drop * sev,
                    "ssim": 0.8 - 0.01 * drop * sev,
                    "miou_3dovs": 0.95 - 0.02 * drop * sev,
                },
            )
    write_run(root, "noise/salt_pepper_5", method="gaussiands", scene="bench", study="depth_noise",
              grid={"priors.depth.noise.type": "salt_pepper", "priors.depth.noise.severity": 5},
              metrics={"psnr": None, "ssim": None, "miou_3dovs": None}, status="failed")


def make_all(root: Path) -> Path:
    make_main(root)
    make_ablations(root)
    make_lambda_noise(root)
    return root
