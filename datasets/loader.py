"""`load_scene`: read a scene folder in its layout and build a `Scene` in the OpenCV convention.

Layouts are registered (`gsbench.datasets.layout_registry`; the built-ins in `builtin_layout.py`):
colmap, llff, nerf, 3dovs, lerf, 3dovs+lerf (alias both), kaolin; `auto` detects one. This module holds
the built-ins' readers. Cameras come from, in order of preference:
  colmap -> sparse/0 (or sparse/ or the folder); llff -> poses_bounds.npy; nerf -> transforms*.json;
  3dovs -> poses_bounds.npy (the 3D-OVS protocol), else COLMAP; lerf / both -> COLMAP, else
  transforms.json, else poses_bounds.npy. Sparse points come from a COLMAP model whenever one exists.
A gsbench synthetic scene (`gsbench_scene.json`) adds GT depth, instances, removal renders and its
explicit split to whichever layout is read (unless the layout says otherwise). Split: explicit lists
when the layout has them, else the LLFF hold-out (index % 8 == 0 -> test).
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from gsbench.camera import Camera
from gsbench.errors import InputError

from . import colmap as colmap_io
from . import kaolin as kaolin_io
from . import layout_registry, ovs
from . import llff as llff_io
from . import nerf as nerf_io
from .base import Scene
from .guard import inside_scene
from .imageio import image_size, list_images, read_gray, read_npy, read_rgb

SYNTHETIC_META = "gsbench_scene.json"
LLFF_HOLD = 8


# ------------------------------------------------------------------------------------ detection
def detect_layout(root: Path) -> str:
    """The layout a folder is in: the first registered layout, in priority order, that recognises it."""
    return layout_registry.detect_layout(root)


def has_3dovs(root: Path) -> bool:
    return (root / "segmentations" / "classes.txt").is_file()


def has_lerf(root: Path) -> bool:
    return ovs.find_label_dir(root) is not None


def llff_split(n: int, hold: int = LLFF_HOLD) -> tuple[list[int], list[int]]:
    """LLFF / 3DGS hold-out: every `hold`-th view (index % hold == 0) is a test view."""
    test = [i for i in range(n) if i % hold == 0] if n > 1 else []
    return [i for i in range(n) if i not in set(test)], test


def camera_extent(cameras: list[Camera]) -> float:
    """3DGS scene radius: 1.1 x the largest distance of a camera centre from their mean (0 if one camera)."""
    c = np.array([cam.center for cam in cameras])
    return float(1.1 * np.max(np.linalg.norm(c - c.mean(0), axis=1))) if len(c) else 0.0


# ------------------------------------------------------------------------------------ cameras
def _from_colmap(root: Path):
    mdir = colmap_io.find_model_dir(root)
    if mdir is None:
        raise InputError(f"{root}: no COLMAP model (sparse/0/cameras.bin|txt)")
    cams, points, colors, meta = colmap_io.read_colmap(mdir)
    img_dir = root / "images"
    names = sorted(cams)
    paths = []
    for n in names:
        p = inside_scene(root, str(Path("images") / n), colmap_io.model_file(mdir, "images"), "image name")
        if not p.is_file():
            raise InputError(f"{p}: image listed in the COLMAP model {mdir} is missing")
        w, h = image_size(p)
        if (w, h) != (cams[n].width, cams[n].height):
            raise InputError(f"{p}: image is {w}x{h}, COLMAP camera says {cams[n].width}x{cams[n].height}")
        paths.append(p)
    if img_dir.is_dir():
        extra = len(list_images(img_dir)) - len(names)
        if extra > 0:
            meta["images_without_pose"] = extra
    meta["poses_from"] = str(mdir)
    return [cams[n] for n in names], paths, points, colors, meta


def _from_llff(root: Path):
    paths = list_images(root / "images")
    sizes = [image_size(p) for p in paths]
    cams, bounds = llff_io.read_poses_bounds(root / "poses_bounds.npy", sizes, [p.name for p in paths])
    return cams, paths, {"poses_from": str(root / "poses_bounds.npy"), "near": float(bounds[:, 0].min()),
                         "far": float(bounds[:, 1].max())}


def _points_if_any(root: Path):
    mdir = colmap_io.find_model_dir(root)
    if mdir is None:
        return None, None
    _, points, colors, _ = colmap_io.read_colmap(mdir)
    return points, colors


def poses_colmap(root: Path) -> tuple:
    """(cameras, image paths, points, colours, train ids, test ids, meta) of a COLMAP folder; the
    `poses_*` readers share this shape (None where a part is absent)."""
    cams, paths, points, colors, meta = _from_colmap(root)
    return cams, paths, points, colors, None, None, meta


def poses_llff(root: Path) -> tuple:
    cams, paths, meta = _from_llff(root)
    return cams, paths, None, None, None, None, meta


def poses_nerf(root: Path) -> tuple:
    cams, paths, train, test, meta = nerf_io.read_transforms(root)
    return cams, paths, None, None, train, test, meta


def poses_3dovs(root: Path) -> tuple:
    """poses_bounds.npy (the 3D-OVS protocol) with a COLMAP model's points when there is one, else COLMAP."""
    if (root / "poses_bounds.npy").is_file():
        cams, paths, meta = _from_llff(root)
        points, colors = _points_if_any(root)
        return cams, paths, points, colors, None, None, meta
    return poses_colmap(root)


def poses_labelled(root: Path) -> tuple:
    """A LERF-OVS scene's cameras: COLMAP, else transforms.json, else poses_bounds.npy."""
    if colmap_io.find_model_dir(root) is not None:
        return poses_colmap(root)
    if (root / "transforms.json").is_file():
        return poses_nerf(root)
    if (root / "poses_bounds.npy").is_file():
        return poses_llff(root)
    raise InputError(f"{root}: no poses (sparse/0, transforms.json or poses_bounds.npy)")


def camera_scene(poses, layout: str):
    """A layout's camera reader: folder -> Scene named `layout` from a `poses_*` reader."""
    def read(root: Path) -> Scene:
        cams, paths, points, colors, train, test, meta = poses(root)
        if train is None:
            train, test = llff_split(len(cams))
            meta["split"] = f"llff-hold-{LLFF_HOLD}"
        loader = _ImageLoader(cams, paths)
        return Scene(name=root.name, path=str(root), layout=layout, cameras=cams, train_ids=train, test_ids=test,
                     image_paths=[str(p) for p in paths], points=points, point_colors=colors,
                     extent=camera_extent(cams), image_loader=loader, meta=meta)
    return read


def _base_scene(root: Path, layout: str) -> Scene:
    """The cameras and images of a folder in a registered layout (no labels; `gsbench data check` reads
    the parts one at a time)."""
    lay = layout_registry.get_layout(layout)
    return lay.cameras(root) if lay.cameras is not None else lay.load(root)


class _ImageLoader:
    """Lazy image reads with the size check against the camera (picklable, for worker processes)."""

    def __init__(self, cams: list[Camera], paths: list[Path]):
        self.sizes = [(c.width, c.height) for c in cams]
        self.paths = [Path(p) for p in paths]

    def __call__(self, i: int) -> np.ndarray:
        return read_rgb(self.paths[i], self.sizes[i])


# ------------------------------------------------------------------------------------ optional parts
def attach_3dovs(scene: Scene, root: Path) -> None:
    seg_dir = root / "segmentations"
    names = ovs.read_classes(seg_dir)
    files = ovs.scan_segmentations(seg_dir, names, len(scene.cameras))
    sizes = [(c.width, c.height) for c in scene.cameras]

    def masks(i: int):
        return ovs.read_class_masks(files[i], names, sizes[i]) if i in files else None

    def classes(i: int):
        m = masks(i)
        return None if m is None else ovs.masks_to_class_map(m, names)

    scene.class_names = names
    scene.class_masks_loader = masks
    scene.classes_loader = classes
    scene.semantic_view_ids = sorted(files)


def attach_lerf(scene: Scene, root: Path) -> None:
    ldir = ovs.find_label_dir(root)
    if ldir is None:
        raise InputError(f"{root}: no LERF-OVS labels (label/{root.name}/frame_XXXXX.json)")
    files = ovs.label_files(ldir, len(scene.cameras))
    queries: set[str] = set()
    parsed = {}
    for i, f in files.items():
        cam = scene.cameras[i]
        info, objs = ovs.read_lerf_label(f, (cam.width, cam.height))
        w, h = ovs.label_size(f, info, cam.name, cam.width, cam.height)
        scene.label_sizes[i] = (w, h)
        scene.raw_labels[i] = objs
        if (w, h) != (cam.width, cam.height):
            objs = ovs.scale_labels(objs, cam.width / float(w), cam.height / float(h))
            scene.meta["labels_rescaled"] = True
        parsed[i] = objs
        queries.update(o.category for o in objs)
    scene.labels_loader = parsed.get
    scene.label_view_ids = sorted(parsed)
    scene.queries = sorted(queries)
    scene.meta["label_dir"] = str(ldir)


def _attach_synthetic(scene: Scene, root: Path) -> None:
    mp = root / SYNTHETIC_META
    meta = nerf_io.read_json_input(mp)
    names = [Path(p).name for p in scene.image_paths]
    if meta.get("image_names") != names:
        raise InputError(f"{mp}: image_names do not match the images of the scene ({len(names)} images)")
    n = len(names)
    train, test = meta.get("train_ids"), meta.get("test_ids")
    if not (isinstance(train, list) and isinstance(test, list) and all(0 <= int(i) < n for i in train + test)):
        raise InputError(f"{mp}: train_ids / test_ids missing or out of range")
    scene.train_ids, scene.test_ids = [int(i) for i in train], [int(i) for i in test]
    scene.meta["split"] = "explicit (gsbench_scene.json)"
    stems = [Path(x).stem for x in names]
    sizes = [(c.width, c.height) for c in scene.cameras]
    gt = inside_scene(root, str(meta.get("gt_dir", "gt")), mp, "gt_dir")

    def depth(i: int) -> np.ndarray:
        p = gt / "depth" / f"{stems[i]}.npy"
        d = read_npy(p)
        if d.shape != (sizes[i][1], sizes[i][0]):
            raise InputError(f"{p}: depth is {d.shape}, image is {sizes[i][1]}x{sizes[i][0]}")
        bad = ~np.isfinite(d)
        if bad.any():   # the format says finite z with 0 where no surface; NaN/inf would poison the depth prior
            raise InputError(f"{p}: depth has {int(np.isnan(d).sum())} NaN and {int(np.isinf(d).sum())} inf pixels "
                             "(expected finite camera-space z, 0 where no surface)")
        return d.astype(np.float32)

    def instances(i: int) -> np.ndarray:
        return read_gray(gt / "instances" / f"{stems[i]}.png", sizes[i]).astype(np.int32) - 1

    removable = [int(k) for k in meta.get("removable_instances", [])]

    def removal(i: int, inst: int):
        if int(inst) not in removable:
            return None
        return read_rgb(gt / "removal" / stems[i] / f"{int(inst):03d}.png", sizes[i])

    scene.depth_loader = depth
    scene.instances_loader = instances
    scene.removal_loader = removal
    scene.removable_instances = removable
    scene.instance_classes = {int(k): v for k, v in meta.get("instance_classes", {}).items()}
    scene.instance_names = {int(k): v for k, v in meta.get("instance_names", {}).items()}
    if not scene.class_names:
        scene.class_names = list(meta.get("class_names", []))  # index space of instance_classes
    scene.meta["synthetic"] = meta.get("generator", {})
    for k in ("near", "far"):  # nearest / farthest surface depth over all views
        if k in meta:
            scene.meta[k] = float(meta[k])
    scene.meta["depth_format"] = "float32 .npy, camera-space z, 0 where no surface"


def kaolin_scene(root: Path) -> Scene:
    cams, rgbs, sems = kaolin_io.read_kaolin(root)
    sizes = [(c.width, c.height) for c in cams]

    def masks(i: int):
        m = read_gray(sems[i], sizes[i])
        return {"background": m == 0, "clock": m == 255}

    def classes(i: int):
        m = read_gray(sems[i], sizes[i])
        out = np.full(m.shape, -1, np.int32)
        out[m == 0] = 0
        out[m == 255] = 1
        return out

    train, test = llff_split(len(cams))
    return Scene(name=root.name, path=str(root), layout="kaolin", cameras=cams, train_ids=train, test_ids=test,
                 image_paths=[str(p) for p in rgbs], class_names=["background", "clock"], extent=camera_extent(cams),
                 classes_loader=classes, class_masks_loader=masks, semantic_view_ids=list(range(len(cams))),
                 image_loader=_ImageLoader(cams, rgbs),
                 meta={"split": f"llff-hold-{LLFF_HOLD}", "poses_from": "views/*_metadata.json (USD tf_mat)",
                       "semantic_paths": [str(p) for p in sems]})


# ------------------------------------------------------------------------------------ public
def load_scene(path: str | Path, layout: str = "auto") -> Scene:
    """Read a scene folder into a `Scene` (OpenCV cameras, lazy images, split, optional GT parts)."""
    root = Path(path)
    if not root.is_dir():
        raise InputError(f"{root}: scene folder not found")
    lay = layout_registry.get_layout(detect_layout(root) if layout == layout_registry.AUTO else layout)
    scene = lay.load(root)
    if not lay.extras:
        return scene
    if (root / SYNTHETIC_META).is_file():
        _attach_synthetic(scene, root)
    _settle_extent(scene)
    return scene


def _settle_extent(scene: Scene) -> None:
    """Cameras sharing one centre (one view, a rotation-only capture) give no camera spread: use the
    sparse points' spread around the centre, else 1.0; `meta["extent_source"]` says which."""
    if scene.extent > 1e-9:
        scene.meta["extent_source"] = "camera centres (3DGS: 1.1 x max distance from their mean)"
    elif scene.has_points:
        c = np.mean([cam.center for cam in scene.cameras], axis=0)
        scene.extent = float(1.1 * np.max(np.linalg.norm(scene.points - c, axis=1)))
        scene.meta["extent_source"] = "sparse points (cameras share one centre)"
    else:
        scene.extent = 1.0
        scene.meta["extent_source"] = "default 1.0 (cameras share one centre and there are no points)"


def scene_fingerprint(path: str | Path, layout: str = "auto") -> str:
    """sha256 of what a run depends on: layout, cameras, split, classes, queries and the image bytes."""
    scene = load_scene(path, layout)
    h = hashlib.sha256()
    head = {"layout": scene.layout, "cameras": [c.to_dict() for c in scene.cameras], "train": scene.train_ids,
            "test": scene.test_ids, "classes": scene.class_names, "queries": scene.queries}
    h.update(json.dumps(head, sort_keys=True).encode())
    for p in scene.image_paths:
        h.update(Path(p).name.encode())
        h.update(hashlib.sha256(Path(p).read_bytes()).digest())
    return h.hexdigest()
