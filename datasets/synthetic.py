"""Synthetic indoor scenes from an analytic ray caster (numpy): an independent ground truth.

A scene is a textured floor (z = 0) and back wall (y = WALL_Y), 3 to 8 objects of distinct classes
(spheres, boxes turned about z, upright cylinders) with procedural textures, and texture-only
regions (a poster on the wall; a rug on the floor in larger presets): class boundaries with no depth
edge. Shading is Lambertian under fixed lights with no shadows, so colour does not depend on the
viewpoint and removing an object changes only the pixels it covered.

Per view the generator writes RGB, GT depth (camera-space z), instance and class maps and, per
object, the view rendered without it. Pixel (col j, row i) is the ray through (j + 0.5, i + 0.5),
the convention of `Camera.project`. Rays are built with camera-space z = 1, so the ray parameter of
a hit is its depth.

Output folder (layout "both"; "3dovs" and "lerf" write the subsets they need):
  images/frame_00001.png ...            RGB (1-based names: label frame_00041 is index 40)
  sparse/0/*.bin                        COLMAP model (PINHOLE cameras, surface sample points)
  poses_bounds.npy                      LLFF poses (3dovs)
  segmentations/classes.txt, segmentations/<idx>/<class>.png  (3dovs; every class of every view)
  label/<preset>/frame_00001.json ...   LERF-OVS polygons of objects and decals (lerf)
  gt/depth/<stem>.npy                   float32 camera-space z, 0 where no surface
  gt/instances/<stem>.png               uint16, instance id + 1, 0 = none
  gt/removal/<stem>/<id>.png            RGB without object <id>
  gsbench_scene.json                    classes, instances, split, queries, generator parameters
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import cv2
import numpy as np

from gsbench.errors import InputError
from gsbench.store import write_json_atomic

from .colmap import write_colmap
from .imageio import write_npy, write_png
from .llff import write_poses_bounds
from .ovs import mask_to_polygons
from .synthetic_render import camera_rays, render_view, trace
from .synthetic_spec import FAR, GENERATOR_VERSION, LAYOUT_CHOICES, PRESETS, WALL_Y, SceneSpec, compose

__all__ = ["make_scene", "parse_resolution", "compose", "render_view", "trace", "camera_rays", "PRESETS",
           "LAYOUT_CHOICES", "WALL_Y", "FAR", "GENERATOR_VERSION", "SceneSpec"]


# ------------------------------------------------------------------------------------ writing
def _sample_points(cam, rgb: np.ndarray, depth: np.ndarray, per: int, rng: np.random.Generator):
    """`per` surface points back-projected from one view's GT depth, coloured by its image (None when
    the view sees no surface). Called view by view, so no more than one view is ever held."""
    valid = np.flatnonzero(depth.ravel() > 0)
    if not len(valid):
        return None
    pick = rng.choice(valid, size=min(per, len(valid)), replace=False)
    o, D = camera_rays(cam)
    return o + depth.ravel()[pick, None] * D[pick], rgb.reshape(-1, 3)[pick]


def _label_json(name: str, W: int, H: int, cmap: np.ndarray, classes: list[str], label_classes: list[str]) -> dict:
    objs = []
    group = 0
    for c in label_classes:
        m = cmap == classes.index(c)
        if not m.any():
            continue
        group += 1
        for poly in mask_to_polygons(m):
            pm = np.zeros((H, W), np.uint8)
            cv2.fillPoly(pm, [poly.reshape(-1, 1, 2)], 1)
            objs.append({"category": c, "group": group, "segmentation": poly.tolist(), "area": float(pm.sum()),
                         "layer": float(group), "bbox": [float(v) for v in (*poly.min(0), *poly.max(0))],
                         "iscrowd": 0, "note": ""})
    return {"info": {"name": name, "width": W, "height": H, "depth": 3, "note": "gsbench synthetic"}, "objects": objs}


def make_scene(preset: str, out: Path, seed: int = 0, views: int | None = None,
               resolution: tuple[int, int] | None = None, layout: str = "both", progress: bool = False,
               points: int | None = None) -> Path:
    """Render a preset into `out` (a new or empty folder). The folder appears whole (temp + rename).
    `points`: the number of sparse points (default: the preset's)."""
    from tqdm import tqdm

    if layout not in LAYOUT_CHOICES:
        raise InputError(f"unknown layout {layout!r}; choose one of {', '.join(LAYOUT_CHOICES)}")
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise InputError(f"{out}: exists and is not an empty folder; choose another --out or remove it")
    spec = compose(preset, seed, views, resolution)
    rng = np.random.default_rng([seed, 1])
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        n_points = int(PRESETS[preset]["points"] if points is None else points)
        if n_points < 1:
            raise InputError(f"points must be at least 1, got {n_points}")
        _write(spec, tmp, preset, preset, seed, layout, rng, progress, tqdm, n_points)
        if out.exists():
            out.rmdir()
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def _write(spec: SceneSpec, root: Path, scene_name: str, preset: str, seed: int, layout: str,
           rng: np.random.Generator, progress: bool, tqdm, n_points: int) -> None:
    cams = spec.cameras
    n = len(cams)
    names = [c.name for c in cams]
    stems = [Path(x).stem for x in names]
    W, H = cams[0].width, cams[0].height
    classes = spec.class_names
    lut = np.full(max(spec.instance_classes) + 2, -1, np.int32)
    for k, v in spec.instance_classes.items():
        lut[k] = v
    label_classes = [c for c in classes if c not in ("floor", "wall")]
    train = [i for i in range(n) if i % 8 != 0]
    test = [i for i in range(n) if i % 8 == 0]
    per = max(1, n_points // max(len(train), 1))
    pts, cols, bounds, near, far = [], [], [], np.inf, -np.inf
    for i in tqdm(range(n), desc="make-scene", disable=not progress):
        traced = trace(spec, cams[i])
        r = render_view(spec, cams[i], traced=traced)
        d = r["depth"][r["depth"] > 0]
        bounds.append([0.9 * float(d.min()), 1.1 * float(d.max())] if d.size else [0.1, FAR])
        if d.size:
            near, far = min(near, float(d.min())), max(far, float(d.max()))
        if i in train:
            got = _sample_points(cams[i], r["rgb"], r["depth"], per, rng)
            if got is not None:
                pts.append(got[0])
                cols.append(got[1])
        write_png(root / "images" / names[i], r["rgb"], atomic=False)
        write_npy(root / "gt" / "depth" / f"{stems[i]}.npy", r["depth"], atomic=False)
        write_png(root / "gt" / "instances" / f"{stems[i]}.png", (r["instances"] + 1).astype(np.uint16), atomic=False)
        for inst in spec.removable:
            rr = render_view(spec, cams[i], exclude=inst, traced=traced, base=r)
            write_png(root / "gt" / "removal" / stems[i] / f"{inst:03d}.png", rr["rgb"], atomic=False)
        cmap = np.where(r["instances"] >= 0, lut[r["instances"]], -1)
        if layout in ("both", "3dovs"):
            for k, c in enumerate(classes):
                write_png(
                    root / "segmentations" / f"{i:03d}" / f"{c}.png",
                    np.where(cmap == k, 255, 0).astype(np.uint8),
                    atomic=False,
                )
        if layout in ("both", "lerf"):
            write_json_atomic(root / "label" / scene_name / f"{stems[i]}.json",
                              _label_json(names[i], W, H, cmap, classes, label_classes))
    write_colmap(root / "sparse" / "0", cams, names, np.concatenate(pts), np.concatenate(cols), binary=True)
    if layout in ("both", "3dovs"):
        (root / "segmentations").mkdir(parents=True, exist_ok=True)
        (root / "segmentations" / "classes.txt").write_text("\n".join(classes) + "\n", encoding="utf-8")
        write_poses_bounds(root / "poses_bounds.npy", cams, np.array(bounds))
    meta = {
        "format": "gsbench-synthetic", "version": GENERATOR_VERSION,
        "near": near, "far": far,
        "generator": {"preset": preset, "seed": seed, "views": n, "resolution": [W, H], "layout": layout},
        "image_names": names, "train_ids": train, "test_ids": test,
        "class_names": classes, "queries": label_classes,
        "instance_classes": {str(k): v for k, v in spec.instance_classes.items()},
        "instance_names": {str(k): v for k, v in spec.instance_names.items()},
        "removable_instances": spec.removable,
        "texture_only_classes": [d.name for d in spec.decals],
        "gt_dir": "gt",
        "depth": "gt/depth/<stem>.npy: float32 camera-space z, 0 where the ray hits nothing",
        "instances": "gt/instances/<stem>.png: uint16, instance id + 1, 0 = none",
        "removal": "gt/removal/<stem>/<id:03d>.png: RGB with object <id> removed",
        "cameras": [c.to_dict() for c in cams],
    }
    write_json_atomic(root / "gsbench_scene.json", meta)


def parse_resolution(text: str) -> tuple[int, int]:
    """'WxH' -> (W, H)."""
    try:
        w, h = text.lower().split("x")
        return int(w), int(h)
    except ValueError:
        raise InputError(f"--resolution must look like 128x96, got {text!r}") from None
