"""The built-in scene layouts (gsbench.datasets.layout_registry): each one's detection, its camera reader
and label parts (gsbench.datasets.loader) and its `gsbench data check` steps (gsbench.datasets.check).

Detection order (`priority`): kaolin, 3dovs+lerf, 3dovs, lerf, colmap, llff, nerf: a folder with 3D-OVS
class masks or LERF-OVS labels is read with them, whatever its cameras are.
"""
from __future__ import annotations

from pathlib import Path

from . import colmap as colmap_io
from . import kaolin as kaolin_io
from .check import check_3dovs_labels, check_kaolin, check_lerf_labels
from .layout_registry import Layout
from .loader import (
    attach_3dovs,
    attach_lerf,
    camera_scene,
    has_3dovs,
    has_lerf,
    kaolin_scene,
    poses_3dovs,
    poses_colmap,
    poses_labelled,
    poses_llff,
    poses_nerf,
)


def _nerf(root: Path) -> bool:
    return (root / "transforms.json").is_file() or (root / "transforms_train.json").is_file()


LAYOUTS = (
    Layout("kaolin", detect=kaolin_io.is_kaolin, read=kaolin_scene, priority=10, extras=False, check=check_kaolin,
           described="views/*_rgb.png"),
    Layout("3dovs+lerf", detect=lambda r: has_3dovs(r) and has_lerf(r), priority=20, aliases=("both",),
           cameras=camera_scene(poses_labelled, "3dovs+lerf"), labels=(attach_3dovs, attach_lerf),
           label_checks=(check_3dovs_labels, check_lerf_labels)),
    Layout("3dovs", detect=has_3dovs, priority=30, cameras=camera_scene(poses_3dovs, "3dovs"),
           labels=(attach_3dovs,), label_checks=(check_3dovs_labels,), described="segmentations/classes.txt"),
    Layout("lerf", detect=has_lerf, priority=40, cameras=camera_scene(poses_labelled, "lerf"),
           labels=(attach_lerf,), label_checks=(check_lerf_labels,), described="label/<scene>/frame_*.json"),
    Layout("colmap", detect=lambda r: colmap_io.find_model_dir(r) is not None, priority=50,
           cameras=camera_scene(poses_colmap, "colmap"), described="sparse/0"),
    Layout("llff", detect=lambda r: (r / "poses_bounds.npy").is_file(), priority=60,
           cameras=camera_scene(poses_llff, "llff"), described="poses_bounds.npy"),
    Layout("nerf", detect=_nerf, priority=70, cameras=camera_scene(poses_nerf, "nerf"), described="transforms.json"),
)
