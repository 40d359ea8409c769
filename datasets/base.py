"""Scene: what every reader returns and every method / evaluation consumes.

A Scene says which optional parts it has (`has_*` properties); consumers skip what is absent and
record `skipped: <reason>`, never invent a value. Images are loaded lazily.

Indices `i` are positions in `cameras` (the sorted image list of the layout).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from gsbench.camera import Camera


@dataclass
class LabelObject:
    """One LERF-OVS label object: a text category and its polygon(s) in pixel coordinates."""

    category: str
    polygons: list          # list of (K x 2) float arrays, pixel coordinates (x, y)
    bbox: Optional[tuple] = None  # (x1, y1, x2, y2)
    area: Optional[float] = None


@dataclass
class Scene:
    """A multi-view scene in the one camera convention (OpenCV, world-to-camera)."""

    name: str
    path: str
    layout: str
    cameras: list[Camera]
    train_ids: list[int]
    test_ids: list[int]
    image_paths: list[str]
    class_names: list[str] = field(default_factory=list)
    points: Optional[np.ndarray] = None          # (M, 3) sparse points for initialisation
    point_colors: Optional[np.ndarray] = None    # (M, 3) in [0, 1]
    extent: float = 1.0                          # scene radius (3DGS: camera-centre spread * 1.1)
    # loaders for optional parts; None = the scene does not have that part
    depth_loader: Optional[Callable[[int], np.ndarray]] = None
    classes_loader: Optional[Callable[[int], np.ndarray]] = None
    instances_loader: Optional[Callable[[int], np.ndarray]] = None
    labels_loader: Optional[Callable[[int], Optional[list]]] = (
        None  # LERF: list[LabelObject] or None (no label file for view)
    )
    removal_loader: Optional[Callable[[int, int], Optional[np.ndarray]]] = None  # (view, instance id) -> RGB without it
    instance_classes: dict = field(default_factory=dict)  # instance id -> class index (synthetic scenes)
    queries: list[str] = field(default_factory=list)      # LERF-OVS text queries of the scene
    image_loader: Optional[Callable[[int], np.ndarray]] = None
    meta: dict = field(default_factory=dict)
    # added by the datasets reader (defaults keep older constructors valid)
    class_masks_loader: Optional[Callable[[int], Optional[dict]]] = None  # 3D-OVS: {class: bool HxW} or None
    semantic_view_ids: list[int] = field(default_factory=list)  # views with 3D-OVS class GT
    label_view_ids: list[int] = field(default_factory=list)     # views with a LERF label file
    label_sizes: dict = field(default_factory=dict)             # view -> (W, H) of its label file (LERF eval size)
    raw_labels: dict = field(default_factory=dict)              # view -> label objects in the label file's pixels
    removable_instances: list[int] = field(default_factory=list)  # instance ids with removal GT
    instance_names: dict = field(default_factory=dict)          # instance id -> name (e.g. "mug")

    # ------------------------------------------------------------------ parts
    @property
    def has_points(self) -> bool:
        return self.points is not None and len(self.points) > 0

    def points_digest(self) -> Optional[str]:
        """The sparse points' identity, recorded with every run: the scene fingerprint covers images and
        cameras only, and the points (the initialisation) of a triangulated capture differ between
        triangulations. None without points."""
        return point_set_digest(self.points) if self.has_points else None

    @property
    def has_depth(self) -> bool:
        return self.depth_loader is not None

    @property
    def has_semantics(self) -> bool:
        """3D-OVS style per-pixel classes over `class_names`."""
        return self.classes_loader is not None and len(self.class_names) > 0

    @property
    def has_instances(self) -> bool:
        return self.instances_loader is not None

    @property
    def has_labels(self) -> bool:
        """LERF-OVS style polygon labels and text queries."""
        return self.labels_loader is not None

    @property
    def has_removal(self) -> bool:
        return self.removal_loader is not None

    def parts(self) -> dict[str, bool]:
        return {"points": self.has_points, "gt_depth": self.has_depth, "semantics": self.has_semantics,
                "instances": self.has_instances, "lerf_labels": self.has_labels, "removal_gt": self.has_removal}

    # ------------------------------------------------------------------ data
    def __len__(self) -> int:
        return len(self.cameras)

    def image(self, i: int) -> np.ndarray:
        """float32 H x W x 3 in [0, 1]."""
        return self.image_loader(i)

    def gt_depth(self, i: int) -> Optional[np.ndarray]:
        """Camera-space z (H x W, float32; 0 or NaN where invalid) or None."""
        return None if self.depth_loader is None else self.depth_loader(i)

    def gt_classes(self, i: int) -> Optional[np.ndarray]:
        """int32 H x W class index into `class_names`, -1 unlabelled; or None."""
        return None if self.classes_loader is None else self.classes_loader(i)

    def gt_instances(self, i: int) -> Optional[np.ndarray]:
        """int32 H x W instance id, -1 none (synthetic scenes); or None."""
        return None if self.instances_loader is None else self.instances_loader(i)

    def gt_labels(self, i: int) -> Optional[list]:
        """LERF-OVS label objects of view i, or None when the view has no label file."""
        return None if self.labels_loader is None else self.labels_loader(i)

    def removed_image(self, i: int, instance_id: int) -> Optional[np.ndarray]:
        """float32 H x W x 3 render of view i without instance `instance_id` (synthetic), or None."""
        return None if self.removal_loader is None else self.removal_loader(i, instance_id)

    def gt_class_masks(self, i: int) -> Optional[dict]:
        """3D-OVS per-class bool masks {class name: H x W} of view i (overlaps kept), or None."""
        return None if self.class_masks_loader is None else self.class_masks_loader(i)


def point_set_digest(points: np.ndarray) -> str:
    """First 16 hex digits of the sha256 of the points' xyz as float64, rows sorted (row order does not count)."""
    xyz = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    xyz = xyz[np.lexsort(xyz.T[::-1])]
    return hashlib.sha256(np.ascontiguousarray(xyz).tobytes()).hexdigest()[:16]
