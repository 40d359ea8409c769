"""Benchmark: how right the weight-free ``sfm`` depth prior is, on real photos and on a synthetic scene.

    .venv/bin/python benchmarks/depth_provider_accuracy.py [--work DIR] [--real ../shared/data/dtu_scan37]
                                                          [--real-widths 400 96] [--preset tabletop-small]
                                                          [--size 256x192] [--holdout 0.1] [--seed 0]

Scenes, kept in --work and reused: a copy of the real capture (--real; `gsbench points` adds its
sparse points) and a synthetic scene (`gsbench make-scene`, then `gsbench points --force`, so its
points are triangulated from its photos as on a real capture rather than sampled on its surfaces).

Table 1, held-out points (both scenes, every training view): each view's visible points (the
provider's visibility test) lose a seeded share --holdout, the prior is densified from the rest,
and the held-out points' disparities (1 / z) score it where it is valid. `sfm` is the provider;
`sfm, no photo` is the same filter guided by a constant image (what the photo's edges add).
Table 2, GT depth (synthetic scene only, every valid pixel of every training view): `sfm` from
all of its points beside the simulated `gt` provider at its default distortion, both through
`compute_depth` as training calls it; the simulated prior also only where `sfm` is valid.

Scores, per view then averaged over views: AbsRel after a least-squares affine fit of the prior's
disparity to the reference disparity (the MiDaS protocol; then |z_fit - z| / z), Spearman rank
correlation (no fit needed), the share of reference points or pixels where the prior is valid, and
the share of pixels in GaussianDS's depth-edge map E_d (Canny 50/150, one dilation). What the
numbers say: docs/priors.md, "Depth from the SfM points".
"""
from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

import gsbench  # noqa: F401  (before torch: gsbench's OpenMP default)
from gsbench.camera import training_size
from gsbench.cli import main as gsbench_main
from gsbench.datasets import load_scene
from gsbench.priors import depth as D
from gsbench.priors import sfm_depth as S
from gsbench.priors.warp import camera_at
from gsbench.resize import resize_nearest
from gsbench.train.losses import depth_edges

GT_DISTORTION = 1.0          # the gt provider's default severity


def run_cli(args: list[str]) -> None:
    rc = gsbench_main(args + ["-q"])
    if rc != 0:
        raise SystemExit(f"depth_provider_accuracy: gsbench {' '.join(args)} failed (exit {rc})")


def real_scene(work: Path, src: Path) -> Path:
    """A copy of the real capture with triangulated points (made once)."""
    out = work / src.name
    if not out.exists():
        shutil.copytree(src, out)
    if not (out / "sparse" / "points_provenance.json").exists():
        run_cli(["points", str(out)])
    return out


def synthetic_scene(work: Path, preset: str, size: tuple[int, int], seed: int) -> Path:
    """The synthetic scene with points triangulated from its photos (made once)."""
    out = work / f"{preset}_{size[0]}x{size[1]}_s{seed}"
    if not (out / "gsbench_scene.json").exists():
        run_cli(["make-scene", "--preset", preset, "--out", str(out), "--seed", str(seed),
                 "--resolution", f"{size[0]}x{size[1]}", "--no-progress"])
    if not (out / "sparse" / "points_provenance.json").exists():
        run_cli(["points", "--force", str(out)])
    return out


def affine_absrel(prior: np.ndarray, ref_z: np.ndarray) -> float:
    """AbsRel of the prior's disparity after the least-squares fit s * prior + t ~ 1 / ref_z."""
    ref = 1.0 / ref_z
    A = np.stack([prior, np.ones_like(prior)], axis=1)
    (s, t), *_ = np.linalg.lstsq(A, ref, rcond=None)
    fit = np.maximum(s * prior + t, 1e-3 * float(np.median(ref)))   # a fit at or below 0 is "very far"
    return float(np.mean(np.abs(1.0 / fit - ref_z) / ref_z))


def scores(prior: np.ndarray, ref_z: np.ndarray) -> tuple[float, float] | None:
    """(affine AbsRel, Spearman) on matching samples; None with fewer than 3 or a constant side."""
    if len(prior) < 3 or np.ptp(prior) <= 0 or np.ptp(ref_z) <= 0:
        return None
    return affine_absrel(prior, ref_z), float(spearmanr(prior, -ref_z).statistic)


def edge_share(values: np.ndarray, valid: np.ndarray) -> float:
    return float(depth_edges(values, valid, 50, 150, 1).mean())


def heldout(scene, size: tuple[int, int] | None, frac: float, seed: int) -> dict[str, list]:
    """Per name, per view: (AbsRel, Spearman, share of held-out points valid, E_d share, points)."""
    tracks = S.point_tracks(scene)
    rows: dict[str, list] = {"sfm": [], "sfm, no photo": []}
    rng = np.random.default_rng(seed)
    for v in scene.train_ids:
        cam = camera_at(scene.cameras[v], size or (scene.cameras[v].width, scene.cameras[v].height))
        wh = (cam.width, cam.height)
        vp = S.visible_points(scene.points, cam, None if tracks is None else tracks.get(v))
        n_out = int(round(frac * len(vp.z)))
        if n_out < 3:
            continue
        out = np.zeros(len(vp.z), dtype=bool)
        out[rng.permutation(len(vp.z))[:n_out]] = True
        used = S.ViewPoints(vp.index[~out], vp.uv[~out], vp.z[~out])
        ix, iy = np.floor(vp.uv[out, 0]).astype(int), np.floor(vp.uv[out, 1]).astype(int)
        image = scene.image(v)
        for name, guide in (("sfm", image), ("sfm, no photo", np.full_like(image, 0.5))):
            vals, valid = S.sfm_disparity(used, guide, wh)
            ok = valid[iy, ix]
            sc = scores(vals[iy, ix][ok], vp.z[out][ok])
            if sc is not None:
                rows[name].append((*sc, float(ok.mean()), edge_share(vals, valid), n_out))
    return rows


def against_gt(scene, seed: int) -> dict[str, list]:
    """Per prior, per view: (AbsRel, Spearman, share of GT pixels valid, E_d share, pixels) vs GT depth.
    The simulated prior is scored twice: everywhere, and only where `sfm` is valid (like for like)."""
    cam0 = scene.cameras[scene.train_ids[0]]
    size = (cam0.width, cam0.height)
    gt_name = f"gt (distortion {GT_DISTORTION:g})"
    sim = D.compute_depth(scene, {"provider": "gt", "distortion": GT_DISTORTION}, scene.train_ids, size, seed=seed)
    sfm = D.compute_depth(scene, {"provider": "sfm"}, scene.train_ids, size, seed=seed)
    rows: dict[str, list] = {gt_name: [], f"{gt_name}, where sfm is valid": [], "sfm": []}
    for v in scene.train_ids:
        z = resize_nearest(np.asarray(scene.gt_depth(v), dtype=np.float64), *size)
        gt_ok = np.isfinite(z) & (z > 1e-6)
        for name, p, mask in ((gt_name, sim[v], sim[v].valid), (f"{gt_name}, where sfm is valid", sim[v], sfm[v].valid),
                              ("sfm", sfm[v], sfm[v].valid)):
            ok = gt_ok & mask
            sc = scores(p.values[ok].astype(np.float64), z[ok])
            if sc is not None:
                rows[name].append((*sc, float(ok.sum() / max(1, gt_ok.sum())), edge_share(p.values, p.valid),
                                   int(ok.sum())))
    return rows


def print_table(title: str, unit: str, groups: list[tuple[str, str, dict[str, list]]]) -> None:
    print(f"\n{title}")
    print(f"| scene | size | prior | views | AbsRel | Spearman | {unit} valid | E_d % |")
    print("|---|---|---|---:|---:|---:|---:|---:|")
    for scene, size, rows in groups:
        for name, per_view in rows.items():
            if not per_view:
                print(f"| {scene} | {size} | {name} | 0 | - | - | - | - |")
                continue
            a = np.asarray(per_view, dtype=np.float64)
            print(f"| {scene} | {size} | {name} | {len(a)} | {a[:, 0].mean():.3f} | {a[:, 1].mean():.3f} | "
                  f"{100 * a[:, 2].mean():.1f} % | {100 * a[:, 3].mean():.2f} |", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default=None, help="folder for the scenes (default: a temporary one)")
    ap.add_argument("--real", default=str(Path(__file__).resolve().parents[1] / ".." / "shared" / "data" /
                                          "dtu_scan37"), help="a real capture with poses (3D-OVS/LLFF layout)")
    ap.add_argument("--real-widths", nargs="+", type=int, default=[400, 96], help="prior widths on the real scene")
    ap.add_argument("--preset", default="tabletop-small")
    ap.add_argument("--size", default="256x192", help="synthetic scene size WxH")
    ap.add_argument("--holdout", type=float, default=0.1, help="share of each view's points held out")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    tmp = None if args.work else tempfile.TemporaryDirectory(prefix="depth_accuracy_")
    work = Path(args.work or tmp.name)
    work.mkdir(parents=True, exist_ok=True)
    w, _, h = args.size.lower().partition("x")
    size = (int(w), int(h))
    groups = []
    real = Path(args.real)
    if real.is_dir():
        scene = load_scene(real_scene(work, real))
        for width in args.real_widths:
            wh = training_size(scene.cameras[scene.train_ids[0]], width)
            groups.append((real.name, f"{wh[0]}x{wh[1]}", heldout(scene, wh, args.holdout, args.seed)))
    else:
        print(f"(no real scene at {real}: its rows are left out)")
    synth = load_scene(synthetic_scene(work, args.preset, size, args.seed))
    groups.append((args.preset, args.size, heldout(synth, None, args.holdout, args.seed)))
    print_table(f"Held-out SfM points ({100 * args.holdout:g} % of each view's visible points, seed {args.seed})",
                "points", groups)
    print_table("Against GT depth (every valid pixel)", "pixels",
                [(args.preset, args.size, against_gt(synth, args.seed))])
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
