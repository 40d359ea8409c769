"""The views a phase trains on: every training camera and image at the training resolution, plus the
first `train.eval_views` test views for the loop's periodic evaluation (`load_views`)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from gsbench.camera import Camera, training_size
from gsbench.config import setting
from gsbench.datasets.splits import split_ids
from gsbench.errors import InputError
from gsbench.resize import resize_rgb
from gsbench.train.residency import DEVICE, data_on, place


@dataclass
class TrainViews:
    """Training and periodic-evaluation views at the training resolution."""

    cameras: dict[int, Camera]
    images: dict[int, torch.Tensor]                   # (H, W, 3) float in [0, 1]
    eval_cameras: dict[int, Camera] = field(default_factory=dict)
    eval_images: dict[int, torch.Tensor] = field(default_factory=dict)


def load_views(scene, config: dict, progress: bool = False,
               device: torch.device | str = "cpu") -> tuple[TrainViews, tuple[int, int]]:
    """Train cameras/images at the training resolution (images on `device`, copied once, or on the host
    with train.data_on=host), plus the
    first `eval_views` test views."""
    train_ids, test_ids = split_ids(scene, config)
    if not train_ids:
        raise InputError(f"{scene.path}: the scene has no training views")
    W, H = training_size(scene.cameras[train_ids[0]], setting(config, "train.max_width"))

    def load(i: int) -> tuple[Camera, torch.Tensor]:
        img = np.asarray(scene.image(i), dtype=np.float32)
        if img.ndim != 3 or img.shape[2] < 3:
            raise InputError(f"{scene.image_paths[i] if scene.image_paths else scene.path}: expected an RGB image, "
                             f"got shape {img.shape}")
        img = img[..., :3]
        img = resize_rgb(img, W, H)        # 3DGS's rule: PIL bicubic on the 8-bit image
        return scene.cameras[i].resized(W, H), torch.from_numpy(np.clip(img, 0.0, 1.0).copy())

    views = TrainViews({}, {})
    for i in train_ids:
        views.cameras[i], views.images[i] = load(i)
    n_eval = int(setting(config, "train.eval_views"))
    test = list(test_ids)
    if n_eval > 0 and test:
        pick = [test[int(j)]
                for j in np.unique(np.linspace(0, len(test) - 1, min(n_eval, len(test))).round().astype(int))]
        for i in pick:
            views.eval_cameras[i], views.eval_images[i] = load(i)
    on = data_on(config)     # the periodic-eval images are few: they stay on the device
    views.images, views.eval_images = place(views.images, device, on), place(views.eval_images, device, DEVICE)
    return views, (W, H)


__all__ = ["TrainViews", "load_views"]
