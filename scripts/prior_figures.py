"""Write the pictures of docs/priors.md: the weight-free priors against GT on tabletop-small.

Usage: python scripts/prior_figures.py [--out docs/img] [--scene DIR | --preset NAME] [--stats [--seeds N ...]]
Without --scene, a scene of --preset (default tabletop-small) is generated into a temporary folder (seed 0).
--stats prints, instead of drawing, what the ordering changes at the default severity: the number
of supervision-target pixels that differ between ordering=pose and ordering=random, and per prior
seed, ordering and new-object rule the adjacent-frame mask IoU (lenient, strict, flow) and the
quality of the targets themselves (gsbench.priors.quality: target pixel accuracy and mIoU).
Each picture is a grid: one column per view, one row per setting; white lines are GT object
edges, colours are mask ids (the same colour in two views means the same id only for tracks).
"""
from __future__ import annotations

import argparse
import logging
import tempfile
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from gsbench.priors import depth as D
from gsbench.priors import masks as M
from gsbench.priors import prepare_priors
from gsbench.priors import segmenter as S
from gsbench.priors.features import gt_class_map
from gsbench.priors.propagation import NEW_OBJECT_RULES
from gsbench.priors.quality import target_classes, target_quality
from gsbench.resize import resize_area, resize_nearest

log = logging.getLogger(__name__)
VIEW_INDEX = (4, 5, 6)        # three neighbouring training views
SCALE = 2
MARGIN = 110


def colour(labels: np.ndarray) -> np.ndarray:
    """Ids to colours (golden-ratio hues), -1 black; RGB uint8."""
    ids = np.where(labels >= 0, labels, 0).astype(np.float64)
    hsv = np.stack([((ids * 0.618034) % 1.0) * 179, np.full_like(ids, 200), np.full_like(ids, 230)], -1)
    rgb = cv2.cvtColor(hsv.astype(np.uint8), cv2.COLOR_HSV2RGB)
    rgb[labels < 0] = 0
    return rgb


def with_gt_edges(rgb: np.ndarray, gt: np.ndarray) -> np.ndarray:
    out = rgb.copy()
    out[S.label_edges(gt)] = 255
    return out


def grid(rows: list[tuple[str, list[np.ndarray]]]) -> np.ndarray:
    """Rows of (label, RGB cells), cells upscaled by SCALE (nearest), label in a left margin."""
    lines = []
    for label, cells in rows:
        big = [cv2.resize(c, None, fx=SCALE, fy=SCALE, interpolation=cv2.INTER_NEAREST) for c in cells]
        row = np.concatenate([np.pad(b, ((2, 2), (2, 2), (0, 0)), constant_values=255) for b in big], 1)
        left = np.full((row.shape[0], MARGIN, 3), 255, np.uint8)
        for k, part in enumerate(label.split("\n")):
            cv2.putText(left, part, (4, 20 + 18 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
        lines.append(np.concatenate([left, row], 1))
    return np.concatenate(lines, 0)


def save(path: Path, img: np.ndarray) -> None:
    if not cv2.imwrite(str(path), cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 9]):
        raise OSError(f"{path}: could not write the picture")
    log.info("wrote %s (%d KB)", path, path.stat().st_size // 1024)


def ordering_stats(scene, size: tuple[int, int], seeds: Sequence[int]) -> None:
    """Print what the ordering changes: differing target pixels (pose vs random, seed 0), and per
    seed, ordering and new-object rule the adjacent mask IoU and the supervision's own quality."""
    views = list(scene.train_ids)
    names = list(scene.class_names)
    gt = [gt_class_map(scene, v, size) for v in views]
    names_iou = {"ordering_adjacent_mask_iou": "lenient", "ordering_adjacent_mask_iou_strict": "strict",
                 "ordering_adjacent_mask_iou_flow": "flow"}
    first: dict = {}
    print("seed  masks                   ordering  tracks  adjacent mask IoU (lenient/strict/flow)  "
          "target pixel acc  target mIoU  per-class target IoU")
    for seed in seeds:
        for rule, mode, per_frame in [("-", "pose", True)] + [(r, m, False) for r in NEW_OBJECT_RULES
                                                              for m in ("pose", "filename", "random")]:
            masks_cfg = {"provider": "simulated"} if per_frame else {"provider": "simulated", "new_objects": rule}
            p = prepare_priors(scene, {"ordering": mode, "masks": masks_cfg}, views, size, None, False, True, True,
                               per_frame_masks=per_frame, seed=seed, progress=False)
            if seed == seeds[0] and rule == "uncarried":
                first[mode] = p
            text = p.feature_provider.encode_text(names)
            pred = [target_classes(p.masks[v], {t: f for (w, t), f in p.mask_features.items() if w == v}, text)
                    for v in views]
            q = target_quality(pred, gt, len(names))
            s = p.stats
            ious = "/".join(f"{s[k]:.3f}" if s.get(k) is not None else "-" for k in names_iou)
            per_class = " ".join(f"{n} {x:.2f}" for n, x in zip(names, q["iou"]) if x is not None)
            label = "per-frame" if per_frame else f"carried, {rule}"
            print(f"{seed:<5d} {label:23s} {mode:9s} {s['mask_tracks']:6d}  {ious:39s}  {q['pixel_acc']:16.3f}  "
                  f"{q['miou']:11.3f}  {per_class}")
    differ = total = 0
    for v in views:
        a, b = first["pose"], first["random"]
        ma, mb = a.masks[v], b.masks[v]
        fa = np.zeros(ma.shape + (512,), np.float32)
        fb = np.zeros_like(fa)
        for m, f, p in ((ma, fa, a), (mb, fb, b)):
            for t in np.unique(m[m >= 0]):
                f[m == t] = p.mask_features[(v, int(t))]
        differ += int((np.abs(fa - fb).max(-1) > 0).sum())
        total += ma.size
    print(f"supervision-target pixels that differ between pose and random (seed {seeds[0]}, uncarried): "
          f"{differ} of {total}")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/img")
    ap.add_argument("--scene", default=None)
    ap.add_argument("--stats", action="store_true", help="print the ordering figures instead of drawing")
    ap.add_argument("--preset", default="tabletop-small", help="synthetic scene preset when --scene is not given")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0], help="prior seeds for --stats")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    from gsbench.datasets.loader import load_scene
    from gsbench.datasets.synthetic import make_scene
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        scene = load_scene(args.scene or make_scene(args.preset, Path(tmp) / "s", seed=0))
        size = (scene.cameras[0].width, scene.cameras[0].height)
        if args.stats:
            ordering_stats(scene, size, args.seeds)
            return
        VIEWS = [sorted(scene.train_ids)[k] for k in VIEW_INDEX]
        gt = {v: M.gt_instance_map(scene, v, size) for v in VIEWS}
        img = {v: resize_area(np.asarray(scene.image(v), np.float32), *size) for v in VIEWS}
        z = {v: resize_nearest(np.asarray(scene.gt_depth(v), np.float32), *size) for v in VIEWS}
        u8 = {v: np.clip(np.rint(img[v] * 255), 0, 255).astype(np.uint8) for v in VIEWS}

        def seg_row(label, knobs):
            return (label, [with_gt_edges(colour(S.segment_view(gt[v], knobs, D.view_rng(0, v, "sim-masks"),
                                                                  img[v], z[v])), gt[v]) for v in VIEWS])

        rows = [("image", [u8[v] for v in VIEWS]),
                ("GT instances", [with_gt_edges(colour(gt[v]), gt[v]) for v in VIEWS])]
        rows += [seg_row(f"severity {s}", S.SegmenterKnobs(*(5 * [float(s)]))) for s in range(4)]
        save(out / "priors_severity.png", grid(rows))

        rows = [("image", [u8[v] for v in VIEWS])]
        for f in S.FAILURES:
            rows.append(seg_row(f"{f} 3\n(others 0)", S.SegmenterKnobs(**{f: 3.0})))
        save(out / "priors_failures.png", grid(rows))

        views = list(scene.train_ids)
        rows = [("image", [u8[v] for v in VIEWS])]
        for label, mode, per_frame in (("per-frame", "pose", True), ("carried,\npose order", "pose", False),
                                       ("carried,\nrandom order", "random", False)):
            p = prepare_priors(scene, {"ordering": mode, "masks": {"provider": "simulated", "severity": 1}},
                               views, size, None, False, True, False, per_frame_masks=per_frame, progress=False)
            rows.append((label, [with_gt_edges(colour(p.masks[v]), gt[v]) for v in VIEWS]))
        save(out / "priors_ordering.png", grid(rows))

        rows = []
        for s in range(4):
            cells = []
            for v in VIEWS:
                d, ok = D.gt_disparity_prior(z[v], D.view_rng(0, v, "gt-depth"), float(s))
                lo, hi = np.percentile(d[ok], [1, 99]) if ok.any() else (0.0, 1.0)
                g = np.clip((d - lo) / max(hi - lo, 1e-9), 0, 1)
                cells.append(cv2.applyColorMap(np.rint(g * 255).astype(np.uint8), cv2.COLORMAP_VIRIDIS)[..., ::-1])
            rows.append((f"depth\ndistortion {s}", cells))
        save(out / "priors_depth.png", grid(rows))


if __name__ == "__main__":
    main()
